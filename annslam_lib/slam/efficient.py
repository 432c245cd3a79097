"""EKF-SLAM for the car-like vehicle, written to scale (notebook 05 "EKF-SLAM", notebook 06
"Victoria Park at scale").

State and covariance
    x = [x, y, phi, l1x, l1y, l2x, l2y, ...]: the LASER pose (``kinematics``) and the
    landmarks in the world frame; P its (n, n) covariance, n = 3 + 2 N, kept as ONE
    C-contiguous array whose UPPER triangle holds the symmetric P (symmetric by
    construction; the lower triangle is filled in only when P is handed out). Its
    transpose is Fortran-contiguous, which lets the BLAS rank-k correction work in place
    (:meth:`EkfSlam._correct`).

Cost (``benchmarks/bench_ekf_slam.py`` measures it against the dense reference)
    - Prediction touches only the 3x3 vehicle block and the 3 x 2N cross covariance.
      The motion Jacobian of one Euler step is F = [[1, 0, f0], [0, 1, f1], [0, 0, 1]], and a
      product of such matrices is again of that form with f0, f1 summed, so consecutive
      odometry steps are COMPOUNDED exactly: each step updates the pose and the 3x3 block
      (plain ``math``, a few microseconds), the sums (f0, f1) accumulate, and the cross
      covariance is multiplied by F_total once, when something next reads it (a scan, a
      GPS fix, a checkpoint). ``tests/test_ekf_slam.py`` proves it equal to step-by-step
      prediction.
    - An update touches only the columns its Jacobian touches: the vehicle and the
      observed landmarks. With H_c (2m x c) the nonzero columns of H,

          HP = H_c P[c, :]                  (2m x n; the rows of P, P symmetric)
          S  = HP[:, c] H_c^T + R,  symmetrised, S = L L^T (Cholesky)
          W^T = L^{-1} HP,  x += W (L^{-1} nu),  P -= W W^T

      The last line is the optimal-gain covariance update P - P H^T S^{-1} H P written as
      a symmetric rank-2m correction, done in place on the upper triangle by BLAS
      ``dsyrk`` (no n x n temporary, no n x n Jacobian; half the memory traffic of a
      full ``dgemm``, which matters because the update is memory-bound). All
      observations of a scan go into ONE update.
    - Landmark augmentation (``observation.inverse_observe``): for new landmarks
      l = g(pose, z), P_ll = J_pose P_vv J_pose^T + J_z R J_z^T, P_l* = J_pose P_v*.

Process noise (notebook 05 "process noise")
    The odometry sample k, taken at t_k, is the control held over [t_k, t_{k+1})
    (``dead_reckoning`` convention). Its error is modelled on what is measured: the
    encoder speed (``sigma_speed``) and the steering angle (``sigma_steer``), mapped to
    the controls (v_c, alpha) by the Jacobian of ``motion.axle_speed``:
    Q_c = M diag(sigma_speed^2, sigma_steer^2) M^T. A full Euler step of length
    Delta_k = t_{k+1} - t_k adds G Q_c G^T = Delta_k^2 B Q_c B^T (B = d rate / d control),
    the ACFR discrete model. Scans and GPS fixes fall inside odometry intervals, so the
    filter predicts to every event time in partial steps tau; each partial step adds
    tau Delta_k B Q_c B^T, so the noise added over one odometry interval does not depend
    on how many events split it (and equals the ACFR value when none does).

Models used here as fast, unchecked copies (each beside its model, with the list of places
to change together): the Euler and midpoint step and its noise (``models.motion``,
"fast copies"), the range-bearing prediction (``models.observation.observe_fast``), the
angle wrap of differences (``models.geometry.wrap_difference``).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import eigh
from scipy.linalg.blas import dsyrk, dtrsm
from scipy.linalg.lapack import dpotrf, dtrtrs

from ..models.geometry import wrap_angle, wrap_difference
from ..models.observation import inverse_observe, observe_fast
from ..perception.association import mahalanobis
from ..models.vehicle import Vehicle
from .base import InnovationError, check_initial

__all__ = ["EkfSlam", "diag_blocks"]

_PI, _TWO_PI = math.pi, 2.0 * math.pi


class EkfSlam:
    """The efficient EKF-SLAM state (x, P) and its operations (module docstring).

    x0 (3,): initial laser pose; P0 (3, 3): its covariance (symmetric, PSD, finite);
    motion_model: 'euler' or 'midpoint' (:class:`SlamConfig`).
    ``slam.dense.DenseEkfSlam`` has the same interface with textbook dense algebra.
    Read the state through :meth:`state` (or ``pose``, ``pose_cov``,
    :meth:`landmark_covs`): between calls the vehicle block lives in Python floats, the
    cross covariance may await its compounded prediction, and ``self.P`` holds only
    its upper triangle up to date.
    """

    def __init__(self, x0, P0, vehicle: Vehicle, motion_model: str = "euler") -> None:
        x0, P0 = check_initial(x0, P0, vehicle, motion_model)
        self._mid = motion_model == "midpoint"
        self.vehicle = vehicle
        self._a, self._b, self._L = vehicle.a, vehicle.b, vehicle.L
        self.x = x0.copy()
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = np.ascontiguousarray(0.5 * (P0 + P0.T))
        # The landmarks' 2x2 marginal blocks, kept compact beside P for gating (the
        # diagonal of P's landmark part, and the x-y covariances): gathering them from P
        # after each update (a cache miss per row) cost more than the rest of the gating.
        self._ld = np.empty(0)
        self._lo = np.empty(0)
        self._load_vehicle()

    # ---- vehicle block held as Python floats between flushes
    def _load_vehicle(self) -> None:
        self._px, self._py, self._pphi = self.x[:3].tolist()
        b = self.P[:3, :3].ravel().tolist()
        self._p = [b[0], b[1], b[2], b[4], b[5], b[8]]
        self._f0 = self._f1 = 0.0
        self._dirty = False
        self._om = None                    # cached gating Jacobians are stale

    def flush(self) -> None:
        """Write the compounded prediction into (x, P): the pose, the 3x3 block, and
        the cross covariance multiplied ONCE by F_total = [[1,0,f0],[0,1,f1],[0,0,1]]."""
        if not self._dirty:
            return
        P, x = self.P, self.x
        x[:3] = (self._px, self._py, self._pphi)
        f0, f1 = self._f0, self._f1
        if P.shape[0] > 3:                 # the upper triangle holds P (see _correct)
            P[:2, 3:] += np.multiply.outer((f0, f1), P[2, 3:])
        p00, p01, p02, p11, p12, p22 = self._p
        n = P.shape[0]
        P.reshape(-1)[[0, 1, 2, n, n + 1, n + 2, 2 * n, 2 * n + 1, 2 * n + 2]] = (
            p00, p01, p02, p01, p11, p12, p02, p12, p22)
        self._f0 = self._f1 = 0.0
        self._dirty = False

    def predict(self, u, dt: float) -> None:
        """One Euler step of ``motion.predict`` of length ``dt`` with the control row
        ``u`` of :func:`~annslam_lib.models.motion.control_table`, process noise
        dt * Delta B Q_c B^T (scalar code: the vehicle block only; the cross covariance
        waits for :meth:`flush`). A step of dt <= 0 does nothing."""
        if dt > 0.0:
            self.predict_many(u, 0.0, (dt,), (u,), record=False)

    def predict_many(self, u, t: float, times, rows, *, record: bool = True):
        """Advance over a stretch of odometry samples in one call (the run loop's step
        between two scans or fixes): holding control ``u`` from time ``t``, for each sample
        k predict to ``times[k]`` (steps of dt <= 0 skipped), then hold ``rows[k]``.
        ``u`` may be None (no control yet: nothing is predicted). Returns (u, t, n, poses):
        the control held and the time reached after the last sample, the number of steps
        taken and, with ``record``, the pose (t, x, y, phi) at every sample.

        The scalar step (the fast copy of ``models.motion.predict`` and its noise; the
        midpoint variant evaluates the rate at phi + dt w / 2) runs on local floats, and the
        motion Jacobians compound into (f0, f1) for :meth:`flush`."""
        a, b, L, mid = self._a, self._b, self._L, self._mid
        px, py, phi = self._px, self._py, self._pphi
        p00, p01, p02, p11, p12, p22 = self._p
        F0, F1 = self._f0, self._f1
        cos, sin = math.cos, math.sin
        n = 0
        poses = [] if record else None
        for tk, row in zip(times, rows):
            dt = tk - t
            if dt > 0.0 and u is not None:
                v, _, ta, w, dw, q00, q01, q11, span = u
                if mid:
                    c, s = cos(phi + 0.5 * dt * w), sin(phi + 0.5 * dt * w)
                else:
                    c, s = cos(phi), sin(phi)
                lx = a * s + b * c
                ly = a * c - b * s
                vx = v * c - w * lx
                f0 = dt * (-v * s - w * ly)
                f1 = dt * vx
                px += dt * vx
                py += dt * (v * s + w * ly)
                phi += dt * w
                if not -_PI < phi <= _PI:
                    phi = _PI - (_PI - phi) % _TWO_PI
                # B = d rate / d (v_c, alpha); noise N = k B Q_c B^T with k = dt * Delta.
                tl = ta / L
                b00, b01 = c - tl * lx, -dw * lx
                b10, b11 = s + tl * ly, dw * ly
                k = dt * span
                g00, g01 = b00 * q00 + b01 * q01, b00 * q01 + b01 * q11   # rows of B Q
                g10, g11 = b10 * q00 + b11 * q01, b10 * q01 + b11 * q11
                g20, g21 = tl * q00 + dw * q01, tl * q01 + dw * q11
                p00, p01, p02, p11, p12, p22 = (
                    p00 + 2.0 * f0 * p02 + f0 * f0 * p22 + k * (g00 * b00 + g01 * b01),
                    p01 + f0 * p12 + f1 * p02 + f0 * f1 * p22 + k * (g00 * b10 + g01 * b11),
                    p02 + f0 * p22 + k * (g00 * tl + g01 * dw),
                    p11 + 2.0 * f1 * p12 + f1 * f1 * p22 + k * (g10 * b10 + g11 * b11),
                    p12 + f1 * p22 + k * (g10 * tl + g11 * dw),
                    p22 + k * (g20 * tl + g21 * dw))
                F0 += f0
                F1 += f1
                n += 1
            if record:
                poses.append((tk, px, py, phi))
            u, t = row, tk
        if n:
            self._px, self._py, self._pphi = px, py, phi
            self._p = [p00, p01, p02, p11, p12, p22]
            self._f0, self._f1 = F0, F1
            self._dirty = True
        return u, t, n, poses

    # ---- read access
    @property
    def n_landmarks(self) -> int:
        return (self.x.size - 3) // 2

    @property
    def pose(self) -> np.ndarray:
        return np.array([self._px, self._py, self._pphi])

    def pose_tuple(self) -> tuple[float, float, float]:
        """The laser pose (x, y, phi) as floats (cheap: no array)."""
        return self._px, self._py, self._pphi

    def pose_cov_entries(self) -> tuple:
        """The six unique entries (p00, p01, p02, p11, p12, p22) of the pose covariance."""
        return tuple(self._p)

    @property
    def pose_cov(self) -> np.ndarray:
        p00, p01, p02, p11, p12, p22 = self._p
        return np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, P) after a flush, P made whole (the arrays themselves, not copies)."""
        self.flush()
        self._symmetrize()
        return self.x, self.P

    def landmarks(self) -> np.ndarray:
        return self.x[3:].reshape(-1, 2)

    def landmark_covs(self) -> np.ndarray:
        """(N, 2, 2) marginal covariances of the landmarks (a strided view of P)."""
        self.flush()
        self._symmetrize()
        return diag_blocks(self.P)

    # ---- observations
    def _sync_blocks(self) -> None:
        """Refresh the compact landmark blocks from P (they drift from it only by rounding)."""
        self._ld = np.diagonal(self.P)[3:].copy()
        self._lo = np.diagonal(self.P, 1)[3::2].copy()

    def observation_model(self, sigma_range: float, sigma_bearing: float):
        """Predicted (range, bearing) of every landmark, zhat (N, 2), and the innovation
        covariances S (N, 2, 2) for gating, elementwise over the landmarks.

        With u = (dx, dy) / r the unit vector to the landmark and w = (-u_y, u_x), the
        Jacobians are H_landmark = J = [u^T; w^T / r] = -H_pose[:, :2] and a heading
        column (0, -1), so H e = J (e_l - e_p) - (0, e_phi) and

            S = [[u'Mu, u'Mw / r - u'm], [., w'Mw / r^2 - 2 w'm / r + P_phiphi]] + R

        with M = Cov(l - p) and m = Cov(l - p, phi). In terms of cos 2theta = u_x^2 - u_y^2
        and sin 2theta = 2 u_x u_y: u'Mu, w'Mw = tr M / 2 -+ A, u'Mw = B with
        A = cos2 (m11 - m00) / 2 - sin2 m01, B = sin2 (m11 - m00) / 2 + cos2 m01.
        About fifty vector operations over the N landmarks instead of N small matrix
        products; the Jacobians are kept for an :meth:`update` from the same state."""
        self.flush()
        N = self.n_landmarks
        if N == 0:
            return np.empty((0, 2)), np.empty((0, 2, 2))
        d = self.x[3:].reshape(N, 2) - (self._px, self._py)
        return self._predicted(d[:, 0], d[:, 1], sigma_range, sigma_bearing)

    def _predicted(self, dx, dy, sigma_range: float, sigma_bearing: float):
        """zhat (N, 2) and S (N, 2, 2) of the landmarks at offsets (dx, dy) from the laser;
        caches their Jacobians for :meth:`update`."""
        r, bearing, a, b, c = self._model(dx, dy, sigma_range, sigma_bearing)
        zhat = np.empty((r.size, 2))
        zhat[:, 0] = r
        zhat[:, 1] = bearing
        S = np.empty((r.size, 2, 2))
        S[:, 0, 0] = a
        S[:, 0, 1] = S[:, 1, 0] = b
        S[:, 1, 1] = c
        return zhat, S

    def _model(self, dx, dy, sigma_range: float, sigma_bearing: float):
        """Predicted range and bearing of every landmark and the entries (S00, S01, S11)
        of its innovation covariance (the closed form of :meth:`observation_model`); the
        Jacobians are cached for an :meth:`update` from the same state."""
        P = self.P
        q = dx * dx + dy * dy
        if q.size and q.min() < 1e-18:
            raise ValueError("a landmark coincides with the sensor position (range < 1e-9 m)")
        r = np.sqrt(q)
        bearing = wrap_difference(np.arctan2(dy, dx) + (_PI / 2 - self._pphi))
        ir = 1.0 / r
        ux, uy = dx * ir, dy * ir
        p00, p01, p02, p11, p12, p22 = self._p
        cx, cy, cphi = P[0, 3:], P[1, 3:], P[2, 3:]        # Cov(x | y | phi, landmarks)
        ld = self._ld
        m00 = ld[0::2] - 2.0 * cx[0::2] + p00              # M = Cov(l - p)
        m01 = self._lo - cx[1::2] - cy[0::2] + p01
        m11 = ld[1::2] - 2.0 * cy[1::2] + p11
        v0 = cphi[0::2] - p02                              # m = Cov(l - p, phi)
        v1 = cphi[1::2] - p12
        cos2 = ux * ux - uy * uy
        sin2 = 2.0 * ux * uy
        half_diff = 0.5 * (m11 - m00)
        half_tr = 0.5 * (m00 + m11)
        A = cos2 * half_diff - sin2 * m01
        s00 = half_tr - A + sigma_range**2
        s01 = (sin2 * half_diff + cos2 * m01) * ir - (ux * v0 + uy * v1)
        s11 = ((half_tr + A) * ir - 2.0 * (ux * v1 - uy * v0)) * ir + (p22 + sigma_bearing**2)
        self._om = [self._px, self._py, self._pphi, self.n_landmarks, (r, bearing),
                    (ux, uy, -uy * ir, ux * ir)]
        return r, bearing, s00, s01, s11

    def innovation_d2(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """Squared Mahalanobis distances d2 (n, N) of the detections z (n, 2) to every
        landmark's predicted measurement: :meth:`observation_model` followed by
        ``perception.association.mahalanobis_fast`` (the same formulas, to the bit), in one
        pass without building zhat and S (the scan's gating is its costliest step after
        the update)."""
        self.flush()
        N = self.n_landmarks
        z = np.asarray(z, dtype=float)
        if N == 0:
            return np.empty((z.shape[0], 0))
        d = self.x[3:].reshape(N, 2) - (self._px, self._py)
        r, bearing, a, b, c = self._model(d[:, 0], d[:, 1], sigma_range, sigma_bearing)
        det = a * c - b * b
        if det.min() <= 0.0 or a.min() <= 0.0:
            S = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
            mahalanobis(z, np.column_stack([r, bearing]), S)    # raises, naming the landmark
        nu_r = z[:, 0, None] - r
        nu_b = wrap_difference(z[:, 1, None] - bearing)
        return (c * nu_r * nu_r - 2.0 * b * nu_r * nu_b + a * nu_b * nu_b) / det

    def update(self, z, lm, sigma_range: float, sigma_bearing: float) -> tuple[float, int]:
        """One batch update with observations z (m, 2) of landmarks lm (m,) (indices;
        a landmark may appear twice). Returns (NIS, dof = 2m)."""
        self.flush()
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        lm_list = lm if type(lm) is list else np.asarray(lm, dtype=np.int64).ravel().tolist()
        m = len(lm_list)
        if m != z.shape[0]:
            raise ValueError(f"update: {z.shape[0]} observations but {m} landmark indices")
        if m and not 0 <= min(lm_list) <= max(lm_list) < self.n_landmarks:
            raise ValueError(f"update: landmark index out of range 0..{self.n_landmarks - 1}")
        if m == 0:
            return 0.0, 0
        uniq = list(dict.fromkeys(lm_list))                # first-seen order
        pos = [uniq.index(j) for j in lm_list] if len(uniq) < m else list(range(m))
        cols = [0, 1, 2]
        for j in uniq:
            cols += (3 + 2 * j, 4 + 2 * j)
        lm = np.array(lm_list)
        om = self._om
        if om is not None and om[:4] == [self._px, self._py, self._pphi, self.n_landmarks]:
            r, bearing = om[4]
            zhat = np.column_stack([r[lm], bearing[lm]])   # from the gating, same state
            Hl = np.empty((m, 2, 2))
            for i, jac in enumerate(om[5]):
                Hl[:, i // 2, i % 2] = jac[lm]
        else:
            zhat, _, Hl = observe_fast(self.x[:3], self.landmarks()[lm])
        k, c = 2 * m, len(cols)
        Hc = np.zeros((k, c))
        Hc[:, :2] = -Hl.reshape(k, 2)
        Hc[1::2, 2] = -1.0
        blocks = Hc[:, 3:].reshape(m, 2, c - 3)            # (obs, row, landmark column)
        p2 = 2 * np.array(pos)
        blocks[np.arange(m), :, p2] = Hl[:, :, 0]
        blocks[np.arange(m), :, p2 + 1] = Hl[:, :, 1]
        nu = z - zhat
        nu[:, 1] = [(b + _PI) % _TWO_PI - _PI for b in nu[:, 1].tolist()]
        return self._correct(np.array(cols), Hc, nu.ravel(),
                             np.array([sigma_range**2, sigma_bearing**2] * m))

    def gps_update(self, xy, sigma_gps: float, gate: float = math.inf) -> tuple[float, bool]:
        """Position fix of the laser point: H = [I2 0 ...]. Rejected (no change) if its NIS
        exceeds ``gate``. Returns (NIS, accepted)."""
        self.flush()
        nu = np.asarray(xy, dtype=float) - self.x[:2]
        nis, _ = self._correct(np.array([0, 1]), np.eye(2), nu, np.full(2, sigma_gps**2), gate)
        return nis, nis <= gate

    def _rows(self, cols) -> np.ndarray:
        """Full rows ``cols`` of the symmetric P from its upper triangle: row c is the
        column above the diagonal, P[:c, c], then the row from the diagonal on, P[c, c:]."""
        P = self.P
        G = np.empty((len(cols), P.shape[0]))
        for r, c in enumerate(cols):
            G[r, :c] = P[:c, c]
            G[r, c:] = P[c, c:]
        return G

    def _symmetrize(self) -> None:
        """Copy the upper triangle (the stored covariance) into the lower one, so that P
        can be read as a whole (checkpoints and results; O(n^2), never per scan)."""
        P = self.P
        lower = np.tril_indices(P.shape[0], -1)
        P[lower] = P.T[lower]

    def _correct(self, cols, Hc, nu, Rd, gate: float = math.inf):
        P = self.P
        HP = Hc @ self._rows(cols)                         # (k, n) = H P
        S = HP[:, cols] @ Hc.T
        S = 0.5 * (S + S.T)
        S.flat[::S.shape[0] + 1] += Rd
        Lc, info = dpotrf(S, lower=1, clean=1)             # S = L L^T
        if info != 0:
            raise InnovationError(
                "innovation covariance S is not positive definite (singular): eigenvalues "
                f"{np.linalg.eigvalsh(S)}; check for zero measurement noise")
        e, info = dtrtrs(Lc, nu, lower=1)                  # e = L^-1 nu
        nis = float(e @ e)
        if not math.isfinite(nis):
            raise ValueError("update produced a non-finite innovation (NaN in the state?)")
        if nis > gate:
            return nis, nu.size
        # W = P H^T L^-T (n, k), Fortran-contiguous: solve W L^T = (HP)^T in place.
        W = dtrsm(1.0, Lc, HP.T, side=1, lower=1, trans_a=1, overwrite_b=1)
        self.x += W @ e
        # P -= W W^T in place, on the upper triangle only (half the memory traffic of a
        # full dgemm; the update is memory-bound): P.T is Fortran-contiguous, so dsyrk
        # writes into P itself, and the Fortran lower triangle of P.T is P's upper one.
        out = dsyrk(-1.0, W, beta=1.0, c=P.T, lower=1, overwrite_c=1)
        if not np.may_share_memory(out, P):       # the silent-copy pitfall: never let it pass
            raise RuntimeError("in-place covariance update worked on a copy")
        if self._lo.size:                                  # the compact landmark blocks too
            Wl = W[3:]
            self._ld -= np.einsum("ij,ij->i", Wl, Wl)
            self._lo -= np.einsum("ij,ij->i", Wl[0::2], Wl[1::2])
        x2 = float(self.x[2])
        if not -_PI < x2 <= _PI:
            self.x[2] = _PI - (_PI - x2) % _TWO_PI
        self._load_vehicle()
        return nis, nu.size

    def augment(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """Add landmarks for observations z (k, 2) from the current pose
        (``observation.inverse_observe``). Returns their indices."""
        self.flush()
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        k = z.shape[0]
        N0 = self.n_landmarks
        if k == 0:
            return np.empty(0, dtype=np.int64)
        lm, Jp, Jz = inverse_observe(self.x[:3], z)
        n = self.x.size
        P = self.P
        Jp2 = Jp.reshape(2 * k, 3)
        A = Jp2 @ self._rows((0, 1, 2))                   # (2k, n) = J_pose P_v*
        Pn = np.empty((n + 2 * k, n + 2 * k))
        Pn[:n, :n] = P
        Pn[n:, :n] = A
        Pn[:n, n:] = A.T
        Pnn = A[:, :3] @ Jp2.T
        R = np.diag([sigma_range**2, sigma_bearing**2])
        JRJ = Jz @ R @ Jz.transpose(0, 2, 1)
        for i in range(k):
            Pnn[2 * i:2 * i + 2, 2 * i:2 * i + 2] += JRJ[i]
        Pn[n:, n:] = 0.5 * (Pnn + Pnn.T)
        self.P = Pn
        self._ld = np.concatenate([self._ld, np.diagonal(Pn)[n:]])
        self._lo = np.concatenate([self._lo, np.diagonal(Pn, 1)[n::2]])
        self.x = np.concatenate([self.x, lm.ravel()])
        self._om = None
        return np.arange(N0, N0 + k)

    def remove(self, idx) -> None:
        """Delete landmarks ``idx`` (marginalise them out: drop their rows and columns).
        Copied block by block between the removed rows: about one copy of P."""
        idx = np.unique(np.asarray(idx, dtype=np.int64).ravel())
        if idx.size == 0:
            return
        self.flush()
        n = self.x.size
        drop = np.sort(np.concatenate([3 + 2 * idx, 4 + 2 * idx]))
        keep = np.ones(n, dtype=bool)
        keep[drop] = False
        starts = np.concatenate([[0], drop + 1])
        ends = np.concatenate([drop, [n]])
        runs = [(a, b) for a, b in zip(starts.tolist(), ends.tolist()) if b > a]
        m = n - drop.size
        Pn = np.empty((m, m))
        P = self.P
        r0 = 0
        for a, b in runs:
            c0 = 0
            for c, d in runs:
                Pn[r0:r0 + b - a, c0:c0 + d - c] = P[a:b, c:d]
                c0 += d - c
            r0 += b - a
        self.P = Pn
        self.x = self.x[keep]
        self._ld = self._ld[keep[3:]]
        self._lo = np.delete(self._lo, idx)
        self._om = None

    def health(self) -> tuple[float, float]:
        """(smallest eigenvalue of P, max |P - P^T|). P is stored as its upper triangle
        (symmetric by construction), so the asymmetry is that of the matrix made whole,
        i.e. zero; the dense reference's is a real measurement."""
        self.flush()
        self._symmetrize()
        self._sync_blocks()
        P = self.P
        lo = float(eigh(P, eigvals_only=True, subset_by_index=[0, 0], check_finite=False)[0])
        return lo, float(np.max(np.abs(P - P.T)))



def diag_blocks(P) -> np.ndarray:
    """The landmarks' 2x2 diagonal blocks of the C-contiguous P as a (N, 2, 2) strided view."""
    n = P.shape[0]
    N = (n - 3) // 2
    s = P.strides[1]
    return np.lib.stride_tricks.as_strided(P[3:, 3:], shape=(N, 2, 2),
                                           strides=((2 * n + 2) * s, n * s, s), writeable=False)
