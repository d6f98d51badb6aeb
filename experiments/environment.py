"""What an episode ran on: the versions of the packages that compute it and the processor.

A closed-loop episode is bit for bit the same on one machine and installation, but not across
them: its outcome turns on small things (a replan 0.1 s apart, a track one frame older), and the
same corridor seeds gave 75.0 % and 65.5 % successes on two machines. Which difference moves them
is not known. Measured here, none of these did (corridor, dodt, the same episodes bit for bit):
numba compiling for haswell instead of the host's znver5 with NumPy's AVX-512 kernels turned off
(seeds 0-19), and OpenBLAS's Haswell kernels instead of its SkylakeX ones (seeds 0-9), although
each changes some results of the libraries by themselves. Left: the library versions and builds,
and Mesa's software renderer. Every episode summary records what is known of its environment, so
that sweeps from different ones are known to be so when compared (``dodt-nav compare`` warns).
"""
from __future__ import annotations

import platform
from functools import lru_cache
from importlib import metadata

# the packages whose arithmetic reaches an episode's outcome
PACKAGES = ("numpy", "scipy", "numba", "llvmlite", "osqp", "casadi", "pybullet", "onnxruntime",
            "opencv-python-headless")

# the x86 SIMD levels between which NumPy's run-time dispatch chooses different kernels
SIMD_LEVELS = ("SSE42", "AVX2", "FMA3", "AVX512F", "AVX512_SKX", "AVX512_ICL", "AVX512_SPR",
               "ASIMD", "SVE")

# the keys that must agree for two episodes to be expected to agree bit for bit
FINGERPRINT_KEYS = ("python", "packages", "cpu", "numpy_simd", "renderer")


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _cpu_model() -> str | None:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def _llvm_cpu() -> str | None:
    """The processor name numba compiles for (its NUMBA_CPU_NAME setting, else the host's)."""
    try:
        import numba
        import llvmlite.binding as llvm
    except ImportError:
        return None
    return numba.config.CPU_NAME or llvm.get_host_cpu_name()


def _numpy_simd() -> list[str]:
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as feats
    except ImportError:  # NumPy 1.x
        try:
            from numpy.core._multiarray_umath import __cpu_features__ as feats
        except ImportError:
            return []
    return [k for k in SIMD_LEVELS if feats.get(k)]


@lru_cache(maxsize=1)
def environment() -> dict:
    """A JSON-able description of this process's machine and installation."""
    return {
        "python": platform.python_version(),
        "packages": {p: _version(p) for p in PACKAGES},
        "cpu": _llvm_cpu(),
        "cpu_model": _cpu_model(),
        "numpy_simd": _numpy_simd(),
    }


def fingerprint(env: dict | None) -> tuple | None:
    """What must agree for outcomes to agree (an episode adds its ``renderer``); None when ``env``
    is missing (results written before episodes recorded it)."""
    if not env:
        return None
    return tuple((k, repr(env.get(k))) for k in FINGERPRINT_KEYS)


def differences(a: dict, b: dict) -> list[str]:
    """The fingerprint entries in which two environments differ, as 'what: A against B'."""
    out = []
    for key in ("python", "cpu", "numpy_simd", "renderer"):
        if a.get(key) != b.get(key):
            out.append(f"{key} {a.get(key)} against {b.get(key)}")
    pa, pb = a.get("packages") or {}, b.get("packages") or {}
    for name in sorted(set(pa) | set(pb)):
        if pa.get(name) != pb.get(name):
            out.append(f"{name} {pa.get(name)} against {pb.get(name)}")
    return out


__all__ = ["PACKAGES", "differences", "environment", "fingerprint"]
