"""Kalman filters over an obstacle's horizontal motion (paper Sec. III-C).

Matrices carry the textbook names: state x, covariance P, transition F, measurement H,
process noise Q, measurement noise R. predict: x = F x, P = F P F^T + Q; update with z:
y = z - H x, S = H P H^T + R, K = P H^T S^-1, x = x + K y, P = (I - K H) P.

Constant acceleration (paper): x = [px, py, vx, vy, ax, ay], F as the paper's A matrix, and
H = I: position, velocity and acceleration are all "measured", the latter two as
pseudo-measurements from the detection history (dodt.tracker). Constant velocity (the
baselines' and w/o FAT's model): x = [px, py, vx, vy], H = I.
"""
from __future__ import annotations

import numpy as np

from dodt.config import KalmanConfig


class KalmanFilter:
    def __init__(self, cfg: KalmanConfig, position: np.ndarray):
        self.cfg = cfg
        self.ca = cfg.model == "ca"
        n = 6 if self.ca else 4
        self.n = n
        self.x = np.zeros(n)
        self.x[:2] = position[:2]
        self.P = np.eye(n) * cfg.p0
        q = [cfg.q_pos] * 2 + [cfg.q_vel] * 2 + ([cfg.q_acc] * 2 if self.ca else [])
        r = [cfg.r_pos] * 2 + [cfg.r_vel] * 2 + ([cfg.r_acc] * 2 if self.ca else [])
        self.Q = np.diag(q)
        self.R = np.diag(r)
        self.H = np.eye(n)
        self._F_dt, self._F = None, None  # the last transition matrix, reused at a steady frame rate

    def F(self, dt: float) -> np.ndarray:
        if dt == self._F_dt:
            return self._F
        F = np.eye(self.n)
        F[0, 2] = F[1, 3] = dt
        if self.ca:
            F[0, 4] = F[1, 5] = 0.5 * dt * dt
            F[2, 4] = F[3, 5] = dt
        self._F_dt, self._F = dt, F
        return F

    def Q_for(self, dt: float, q_scale: float = 1.0) -> np.ndarray:
        """Process noise: the reference code's constant diagonal Q, given per frame of its 30 Hz
        filter, times ``q_scale`` (dt in such frames: the variance a random walk adds grows with
        time), or, with ``measurement = "position"``, the discretised white-jerk (CA) or
        white-acceleration (CV) model with spectral density q (Bar-Shalom, Li, Kirubarajan 2001,
        Sec. 6.2-6.3)."""
        if self.cfg.measurement != "position":
            return self.Q if q_scale == 1.0 else self.Q * q_scale
        q = self.cfg.q_white
        if self.ca:
            blk = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                                [dt**3 / 6, dt**2 / 2, dt]])
        else:
            blk = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        Q = np.zeros((self.n, self.n))
        m = blk.shape[0]
        for a in range(2):  # x and y, interleaved as [x, y, vx, vy, ax, ay]
            idx = [a + 2 * i for i in range(m)]
            Q[np.ix_(idx, idx)] = blk
        return Q

    def predict(self, dt: float, q_scale: float = 1.0) -> None:
        """x = F x, P = F P F^T + Q; ``q_scale`` scales the per-frame Q (Q_for)."""
        F = self.F(dt)
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + self.Q_for(dt, q_scale)

    def update(self, z: np.ndarray, window: float = 1.0, weak_axis: np.ndarray | None = None,
               weak_factor: float = 1.0, position_only: bool = False) -> None:
        """Update with z = [x, y, vx, vy, (ax, ay)], or only [x, y] when measuring position (the
        configuration's ``measurement``, or ``position_only`` for this update).

        ``window`` in (0, 1]: the pseudo-measurements' span over the full averaging window. A
        finite difference over a fraction w of it is 1/w times noisier in velocity and 1/w^2 in
        acceleration, so their R entries grow by 1/w^2 and 1/w^4 (ours: the reference code
        uses one R from the first frame on, and a young track overshoots).
        ``weak_axis``: a horizontal unit vector along which every measured quantity's variance is
        ``weak_factor`` times larger (a detection whose extent along it is unsure).
        """
        z = np.asarray(z, float)
        if self.cfg.measurement == "position" or position_only:
            H = self.H[:2]
            R = self.R[:2, :2].copy()
            z = z[:2]
        else:
            H, R = self.H, self.R.copy()
            z = z[: self.n]
            w = min(max(window, 1e-3), 1.0)
            R[2:4, 2:4] /= w * w
            if self.ca:
                R[4:6, 4:6] /= w**4
        if weak_axis is not None and weak_factor != 1.0:
            a = np.asarray(weak_axis, float)
            stretch = np.eye(2) + (weak_factor - 1.0) * np.outer(a, a)  # eigenvalue weak_factor along a, 1 across
            for i in range(0, len(z), 2):
                R[i:i + 2, i:i + 2] = R[i, i] * stretch  # the blocks are isotropic: r I
        if H is self.H:  # H = I: the same formulas without the products by H
            y = z - self.x
            K = np.linalg.solve(self.P + R, self.P).T
            self.x = self.x + K @ y
            self.P = self.P - K @ self.P
            return
        y = z - H @ self.x
        S = H @ self.P @ H.T + R
        K = np.linalg.solve(S, H @ self.P).T  # P H^T S^-1 (S symmetric)
        self.x = self.x + K @ y
        self.P = (np.eye(self.n) - K @ H) @ self.P

    def limit_speed(self, v_max: float | None) -> float:
        """Scale the state's velocity down to at most ``v_max`` (m/s; None: no bound), keeping its
        direction. Returns the speed before (what the filter alone would have said)."""
        speed = float(np.hypot(self.x[2], self.x[3]))
        if v_max is not None and speed > v_max:
            self.x[2:4] *= v_max / speed
        return speed

    @property
    def position(self) -> np.ndarray:
        return self.x[:2]

    @property
    def velocity(self) -> np.ndarray:
        return self.x[2:4]

    @property
    def acceleration(self) -> np.ndarray:
        return self.x[4:6] if self.ca else np.zeros(2)

    @property
    def position_variance(self) -> float:
        return float((self.P[0, 0] + self.P[1, 1]) / 2)
