"""What an episode ran on: the versions of the packages that compute it and the processor.

A closed-loop episode is bit for bit the same on one machine and installation, but not across
them: its outcome turns on small things (a replan 0.1 s apart, a track one frame older), and the
same seeds and code can give different success rates on two machines. What changes the episodes
(docs/experiments.md, 2026-11-25, has the measurements):

- not the processor numba compiles for, NumPy's AVX-512 kernels, or NumPy's and SciPy's minor
  versions: the episodes stay the same bit for bit;
- OpenBLAS's kernel set, which it picks by itself from the processor unless the environment names
  one (OPENBLAS_CORETYPE), and Mesa's software rasteriser (llvmpipe, behind PyBullet's EGL plugin),
  which compiles its shaders for the host processor and draws some pixels at triangle edges
  otherwise with its SIMD off (GALLIUM_NOSSE=1): every episode can change.

So the record holds the processor, the BLAS kernels, the renderer and Mesa's version beside the
packages, and the variables set by hand that change how they compute; sweeps from different
environments are known to be so when compared (``dodt-nav compare`` warns).
"""
from __future__ import annotations

import os
import platform
from functools import lru_cache
from importlib import metadata

# the packages whose arithmetic reaches an episode's outcome
PACKAGES = ("numpy", "scipy", "numba", "llvmlite", "osqp", "pybullet", "onnxruntime",
            "opencv-python-headless")

# the x86 SIMD levels between which NumPy's run-time dispatch chooses different kernels
SIMD_LEVELS = ("SSE42", "AVX2", "FMA3", "AVX512F", "AVX512_SKX", "AVX512_ICL", "AVX512_SPR",
               "ASIMD", "SVE")

# the keys that must agree for two episodes to be expected to agree bit for bit
FINGERPRINT_KEYS = ("python", "packages", "cpu", "numpy_simd", "blas_core", "mesa", "overrides", "renderer")

# environment variables that change how the libraries compute (set by hand, for tests like the above)
OVERRIDE_PREFIXES = ("GALLIUM_", "GALLIVM_", "LP_", "NUMBA_CPU_", "NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES",
                     "OPENBLAS_", "OPENCV_CPU_DISABLE")
# (thread counts are left out: a Dask worker sets OPENBLAS_NUM_THREADS=1 and its episodes are the
# same bit for bit as local ones, tests/experiments/test_sweep.py)


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


def _blas_core() -> str | None:
    """The kernel set NumPy's OpenBLAS runs on this processor (it picks one at load time, unless
    OPENBLAS_CORETYPE names one), or None where NumPy carries no OpenBLAS of that kind."""
    import ctypes
    import glob

    import numpy

    for path in sorted(glob.glob(os.path.join(os.path.dirname(numpy.__file__), os.pardir, "numpy.libs", "*openblas*"))):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                return fn().decode("ascii", "replace")
    return None


def _mesa() -> str | None:
    """The installed Mesa package's version where the system says (Debian's dpkg), else None."""
    import shutil
    import subprocess

    if not shutil.which("dpkg-query"):
        return None
    for pkg in ("libgl1-mesa-dri", "libegl-mesa0"):
        try:
            r = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", pkg], capture_output=True, text=True,
                               timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        if r.returncode == 0 and r.stdout.strip():
            return r.stdout.strip()
    return None


@lru_cache(maxsize=1)
def environment() -> dict:
    """A JSON-able description of this process's machine and installation."""
    return {
        "python": platform.python_version(),
        "packages": {p: _version(p) for p in PACKAGES},
        "cpu": _llvm_cpu(),
        "cpu_model": _cpu_model(),
        "numpy_simd": _numpy_simd(),
        "blas_core": _blas_core(),
        "mesa": _mesa(),
        "overrides": {k: v for k, v in sorted(os.environ.items())
                      if k.startswith(OVERRIDE_PREFIXES) and not k.endswith("_NUM_THREADS")},
    }


# names episodes recorded for a renderer before it was renamed: the same renderer
_RENDERER_ALIASES = {"egl": "pybullet"}


def _value(env: dict, key: str):
    v = env.get(key)
    return _RENDERER_ALIASES.get(v, v) if key == "renderer" else v


def fingerprint(env: dict | None) -> tuple | None:
    """What must agree for outcomes to agree (an episode adds its ``renderer``); None when ``env``
    is missing (results written before episodes recorded it)."""
    if not env:
        return None
    return tuple((k, repr(_value(env, k))) for k in FINGERPRINT_KEYS)


def distinct(envs) -> list[dict]:
    """The environments of ``envs`` (dicts, or None for unrecorded ones: left out) with different
    fingerprints, first seen first."""
    out = {}
    for env in envs:
        if env:
            out.setdefault(fingerprint(env), env)
    return list(out.values())


def differences(a: dict, b: dict) -> list[str]:
    """The fingerprint entries in which two environments differ, as 'what: A against B'."""
    out = []
    for key in FINGERPRINT_KEYS:
        if key != "packages" and _value(a, key) != _value(b, key):
            out.append(f"{key} {a.get(key)} against {b.get(key)}")
    pa, pb = a.get("packages") or {}, b.get("packages") or {}
    for name in sorted(set(pa) | set(pb)):
        if pa.get(name) != pb.get(name):
            out.append(f"{name} {pa.get(name)} against {pb.get(name)}")
    return out


__all__ = ["PACKAGES", "differences", "distinct", "environment", "fingerprint"]
