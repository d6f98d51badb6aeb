"""Euclidean distance transforms of a 2D grid: from each cell to the nearest feature cell, in cells.

exact_distance: Meijster, Roerdink and Hesselink's two-pass algorithm on integer squared distances,
compiled: the squared distance from each cell to the nearest feature cell is exact, so its square root
(correctly rounded) is the same float as scipy.ndimage.distance_transform_edt's, which takes the root of
the same integer sum.
opencv_distance: OpenCV's precise Euclidean transform (DIST_MASK_PRECISE), computed in float32. Through
Intel IPP (OpenCV's default where it is built in) it is within a float32 rounding step or so of the exact
distance, not always the correctly rounded one, and not always the same floats from call to call on the
same input (opencv/opencv#24082); without IPP (cv2.ipp.setUseIPP(False)) it is exact_distance rounded to
float32.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _edt(feature):
    nx, ny = feature.shape
    inf = nx + ny  # beyond any distance on the grid: squares stay exact in int64
    g = np.empty((nx, ny), np.int64)
    for i in range(nx):  # distance along j to the nearest feature of the row
        g[i, 0] = 0 if feature[i, 0] else inf
        for j in range(1, ny):
            g[i, j] = 0 if feature[i, j] else g[i, j - 1] + 1
        for j in range(ny - 2, -1, -1):
            if g[i, j + 1] < g[i, j]:
                g[i, j] = g[i, j + 1] + 1
    out = np.empty((nx, ny))
    s = np.empty(nx, np.int64)
    t = np.empty(nx, np.int64)
    for j in range(ny):  # lower envelope of the parabolas (u - i)^2 + g(i)^2 along i
        q = 0
        s[0], t[0] = 0, 0
        for u in range(1, nx):
            while q >= 0 and (t[q] - s[q]) ** 2 + g[s[q], j] ** 2 > (t[q] - u) ** 2 + g[u, j] ** 2:
                q -= 1
            if q < 0:
                q = 0
                s[0] = u
            else:
                w = 1 + (u * u - s[q] * s[q] + g[u, j] ** 2 - g[s[q], j] ** 2) // (2 * (u - s[q]))
                if w < nx:
                    q += 1
                    s[q], t[q] = u, w
        for u in range(nx - 1, -1, -1):
            out[u, j] = math.sqrt(float((u - s[q]) ** 2 + g[s[q], j] ** 2))
            if u == t[q]:
                q -= 1
    return out


def exact_distance(feature: np.ndarray) -> np.ndarray:
    """(nx, ny) float64 Euclidean distance, in cells, from each cell to the nearest True cell of
    ``feature`` (at least one must be True): scipy.ndimage.distance_transform_edt(~feature), bit for bit."""
    return _edt(np.ascontiguousarray(feature, dtype=np.bool_))


def opencv_distance(feature: np.ndarray) -> np.ndarray:
    """(nx, ny) float64 Euclidean distance, in cells, from each cell to the nearest True cell of
    ``feature`` (at least one must be True), as OpenCV's precise transform gives it in float32."""
    return cv2.distanceTransform((~feature).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(float)
