"""Segment energies, mechanical work w and power p (W/kg) from motion (SCIENCE.md section 2).

For every segment s and frame k::

    E_s(k) = m_s g z_s + 1/2 m_s |v_s|^2 + 1/2 omega_s^T I_s omega_s,
    I_s = m_s L_s^2 diag(r_sag^2, r_trans^2, r_long^2) in the segment frame.

* w(k): sum over segments of |E_s(j) - E_s(j-1)| over the last ``window_s`` (1 s) of time,
  divided by the body mass M and the window length: no energy transfer between segments.
* p(k): the same sum over the last ``power_window_s`` (0.25 s), an instantaneous rate smoothed
  over a short window.

Choices (named parameters):

* Joint positions (and the rotation matrices of the segments' frames) are low-pass filtered with
  a 2nd-order Butterworth at ``cutoff_hz`` = 6 Hz: zero-phase (forward-backward) for files,
  causal for streams. Both start from the steady state of the first frame. The stream integrates
  the filter's continuous-time equation over each frame's own ``dt_s`` (trapezoidal rule,
  pre-warped at the cut-off), so a game whose frame time varies gets the same 6 Hz filter; at a
  constant ``dt_s`` it is exactly the causal file filter.
* Consistent differences: the energy of frame k is taken at the half frame t(k-1/2), with the
  positions averaged over frames k-1 and k and the velocities (x(k) - x(k-1)) / dt, the central
  difference about that instant. Kinetic and potential energy therefore refer to the same
  instant (a freely falling body does no work; a backward velocity with the frame's own height
  would make it do g^2 dt / 2 W/kg). Angular velocity comes from consecutive segment rotations,
  ``log(R(k) R(k-1)^T) / dt``; without rotations (plain positions) it comes from the turn of the
  segment's long axis, so spin about the long axis is not seen.
* Windows are measured in seconds of time, not in frames: a frame's |dE| is spread over its own
  interval dt_s and the window keeps the part of it that falls in the last ``window_s``. A stream
  fed at 30, 60 or 120 fps, or with jittering frame times, measures the same work.
* Segment frame: long axis from the proximal to the distal end; sagittal (antero-posterior) axis is
  the body's forward direction (from the hip joints and the vertical) made orthogonal to the long
  axis (the vertical when the segment points forward, as a foot does); transverse completes it.
* The first two frames contribute no work (the first has no velocity).
* Loads: point masses at the hand CMs, and on the back :data:`~effortface.train.segments.BACK_LOAD_OFFSET_M`
  behind the trunk CM, added to that segment's energy. M stays the character's own mass.

Paths: :func:`work_and_power` for a whole clip (zero-phase or causal), :class:`EnergyStream` one
frame at a time (equal to the causal whole-clip path), :class:`EnergyCrowd` for N characters at once.
numpy and scipy only (the runtime imports this module).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy import signal

from effortface.core.errors import UserError
from effortface.train.motion import Motion
from effortface.train.segments import BACK_LOAD_OFFSET_M, BodyModel, stack_bodies

#: Gravitational acceleration, m/s^2.
G_M_PER_S2 = 9.81
_EZ = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class SegmentEnergies:
    """Per-frame, per-segment energies in joules, shape (T, S) each (loads included)."""

    t_s: np.ndarray
    potential_j: np.ndarray
    translational_j: np.ndarray
    rotational_j: np.ndarray
    segment_names: tuple[str, ...]

    @property
    def total_j(self) -> np.ndarray:
        """E_s(k), shape (T, S)."""
        return self.potential_j + self.translational_j + self.rotational_j


@dataclasses.dataclass(frozen=True)
class EnergyCurves:
    """Work and power per frame.

    Attributes
    ----------
    t_s : ndarray, shape (T,)
    w_per_kg : ndarray, shape (T,)
        Work over the last window, W/kg.
    p_per_kg : ndarray, shape (T,)
        Power over the last short window, W/kg.
    rate_j_per_kg : ndarray, shape (T,)
        Per-frame sum over segments of |dE_s| / M (J/kg), the quantity both windows sum.
    """

    t_s: np.ndarray
    w_per_kg: np.ndarray
    p_per_kg: np.ndarray
    rate_j_per_kg: np.ndarray


# --------------------------------------------------------------------------------------------
# filtering


def butterworth_sos(cutoff_hz: float, fps: float, order: int = 2) -> np.ndarray:
    """Second-order sections of a low-pass Butterworth filter.

    Parameters
    ----------
    cutoff_hz : float
        Cut-off frequency, below the Nyquist frequency fps / 2.
    fps : float
        Sampling rate (frames per second).
    order : int
        Filter order (2 by default).

    Returns
    -------
    ndarray, shape (n_sections, 6)

    Raises
    ------
    UserError
        If the cut-off is not between 0 and fps / 2.
    """
    if not 0 < cutoff_hz < fps / 2:
        raise UserError(
            f"cutoff_hz: expected a value between 0 and fps/2 = {fps / 2:g} Hz, got {cutoff_hz!r}")
    return signal.butter(order, cutoff_hz, btype="low", fs=fps, output="sos")


def filter_frames(x: np.ndarray, sos: np.ndarray, *, zero_phase: bool) -> np.ndarray:
    """Low-pass filter along axis 0 (frames), starting from the first frame's steady state.

    Parameters
    ----------
    x : ndarray, shape (T, ...)
    sos : ndarray
        Second-order sections (see :func:`butterworth_sos`).
    zero_phase : bool
        Forward-backward (files) or causal (streams; identical to :class:`EnergyStream`).

    Returns
    -------
    ndarray, same shape as ``x``
    """
    # channels-first and contiguous: scipy filters the last axis much faster
    flat = np.ascontiguousarray(x.reshape(x.shape[0], -1).T)
    padlen = max(min(3 * (2 * len(sos) + 1), flat.shape[1] - 1), 0)
    if len(sos) == 1:  # one section: lfilter runs the same recursion about twice as fast
        b, a = sos[0, :3], sos[0, 3:]
        if zero_phase:
            out = signal.filtfilt(b, a, flat, axis=-1, padlen=padlen)
        else:
            out, _ = signal.lfilter(b, a, flat, axis=-1, zi=signal.lfilter_zi(b, a)[None, :] * flat[:, :1])
    elif zero_phase:
        out = signal.sosfiltfilt(sos, flat, axis=-1, padlen=padlen)
    else:
        zi = signal.sosfilt_zi(sos)[:, None, :] * flat[:, :1]
        out, _ = signal.sosfilt(sos, flat, axis=-1, zi=zi)
    return out.T.reshape(x.shape)


# --------------------------------------------------------------------------------------------
# kinematics -> energies (shared by the whole-clip path and the stream)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors along the last axis and the norms (zero vectors stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12), n[..., 0]


def _rotation_vector(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of ``b @ a^T`` for rotation matrices a (previous) and b, shape (..., 3)."""

    def rel(i: int, k: int) -> np.ndarray:  # (b @ a^T)[i, k], without a slow batched 3x3 matmul
        return np.sum(b[..., i, :] * a[..., k, :], axis=-1)

    vee = 0.5 * np.stack([rel(2, 1) - rel(1, 2), rel(0, 2) - rel(2, 0), rel(1, 0) - rel(0, 1)], axis=-1)
    axis, sin_angle = _unit(vee)
    cos_angle = 0.5 * (np.sum(b * a, axis=(-2, -1)) - 1.0)
    return axis * np.arctan2(sin_angle, cos_angle)[..., None]


def _axis_turn(u_prev: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) turning unit vector u_prev onto u (no spin about the axis)."""
    axis, sin_angle = _unit(np.cross(u_prev, u))
    return axis * np.arctan2(sin_angle, np.sum(u_prev * u, axis=-1))[..., None]


def _backward_diff(x: np.ndarray, dt_s: float) -> np.ndarray:
    """(x[k] - x[k-1]) / dt along axis 0, with zero for the first frame."""
    d = np.zeros_like(x)
    d[1:] = (x[1:] - x[:-1]) / dt_s
    return d


def _forward_axes(pos: np.ndarray, body: BodyModel) -> np.ndarray:
    """Body forward direction per frame, shape (T, 3): hip line x vertical (x axis if degenerate)."""
    left, right = body.hip_joints
    fwd, norm = _unit(np.cross(pos[..., left, :] - pos[..., right, :], _EZ))
    fwd[norm < 1e-9] = (1.0, 0.0, 0.0)
    return fwd


def _segment_axes(u: np.ndarray, fwd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sagittal and transverse unit axes (T, S, 3) for long axes u (T, S, 3)."""
    a = fwd[..., None, :] - np.sum(fwd[..., None, :] * u, axis=-1, keepdims=True) * u
    up = _EZ - u[..., 2:3] * u
    a, norm = _unit(a)
    a = np.where((norm < 0.3)[..., None], _unit(up)[0], a)
    return a, np.cross(u, a)


def _half_frames(x: np.ndarray) -> np.ndarray:
    """Values at the half frames t(k-1/2): means of frames k-1 and k along axis 0 (frame 0 kept)."""
    mid = x.copy()
    mid[1:] = 0.5 * (x[1:] + x[:-1])
    return mid


def _central_diff(x: np.ndarray, dt_s: float) -> np.ndarray:
    """(x[k+1] - x[k-1]) / (2 dt) along axis 0; one-sided at the two ends, zero for one frame."""
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.gradient(x, dt_s, axis=0)


def _central_turn(turn: Callable[[np.ndarray, np.ndarray], np.ndarray], a: np.ndarray,
                  dt_s: float) -> np.ndarray:
    """Angular velocity at every frame from a frame-pair turn function, central where possible."""
    if a.shape[0] < 2:
        return turn(a, a)  # no turn: zeros of the right shape
    return np.concatenate([turn(a[:1], a[1:2]), 0.5 * turn(a[:-2], a[2:]),
                           turn(a[-2:-1], a[-1:])]) / dt_s


def _joint_mix(weights: np.ndarray, pos_m: np.ndarray) -> np.ndarray:
    """``weights @ pos_m`` for weights (S, J) shared by every frame and character, pos (..., J, 3).

    One matrix product over all frames and characters (numpy's broadcast ``@`` runs one small
    product per frame and character, many times slower for a crowd).
    """
    return np.swapaxes(np.tensordot(pos_m, weights, axes=([-2], [1])), -1, -2)


def _segment_points(body: BodyModel, pos_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment CMs and long-axis vectors (distal - proximal end), each (..., S, 3).

    The CM is ``proximal + com_frac (distal - proximal)``; the end points are shared-weight
    products (:func:`_joint_mix`), so a crowd's per-character ``com_frac`` costs one multiply.
    """
    prox = _joint_mix(body.proximal_weights, pos_m)
    limb = _joint_mix(body.distal_weights, pos_m) - prox
    return prox + body.com_frac[..., None] * limb, limb


def _kinematic_state(pos_m: np.ndarray, frame_rot: np.ndarray | None, dt_s: float, body: BodyModel,
                     centred: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, CM positions, CM velocities and angular velocities at the scheme's instants."""
    com, limb = _segment_points(body, pos_m)
    if centred:
        v = _central_diff(com, dt_s)
        if frame_rot is not None:
            omega = _central_turn(_rotation_vector, frame_rot, dt_s)
        else:
            omega = _central_turn(_axis_turn, _unit(limb)[0], dt_s)
        return pos_m, com, v, omega
    v = _backward_diff(com, dt_s)
    omega = np.zeros(com.shape)
    if frame_rot is not None:
        omega[1:] = _rotation_vector(frame_rot[:-1], frame_rot[1:]) / dt_s
    else:
        u_frame, _ = _unit(limb)
        omega[1:] = _axis_turn(u_frame[:-1], u_frame[1:]) / dt_s
    return _half_frames(pos_m), _half_frames(com), v, omega


def kinematic_energies(
    pos_m: np.ndarray, frame_rot: np.ndarray | None, dt_s: float, body: BodyModel, *,
    centred: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Potential, translational and rotational energy (J), each (T, S), of filtered kinematics.

    Kinetic and potential energy always refer to the same instant (free fall does no work):

    * ``centred=False`` (causal: streams and the causal file path): frame k's energies are taken
      at the half frame t(k-1/2), positions being the means of frames k-1 and k and velocities
      their central difference (x(k) - x(k-1)) / dt about that instant.
    * ``centred=True`` (zero-phase file path): at frame k itself, with the central difference
      (x(k+1) - x(k-1)) / (2 dt) (one-sided at the clip's two ends).

    Parameters
    ----------
    pos_m : ndarray, shape (T, J, 3) or (T, N, J, 3)
        Filtered joint positions, metres, Z up (N characters with a stacked body).
    frame_rot : ndarray, shape (T, [N,] S, 3, 3), or None
        Filtered rotation of each segment's frame joint, or None (long-axis turn only).
    dt_s : float
        Frame interval in seconds.
    body : BodyModel
        One body, or N bodies stacked by :func:`~effortface.train.segments.stack_bodies`.
    centred : bool
        The scheme, see above.

    Returns
    -------
    potential_j, translational_j, rotational_j : ndarray, shape (T, [N,] S)
        Loads are included in their segment's energy.
    """
    m, ml = body.segment_mass_kg, body.load_kg
    at, com_at, v, omega = _kinematic_state(pos_m, frame_rot, dt_s, body, centred)
    pot = (m + ml) * G_M_PER_S2 * com_at[..., 2]
    trans = 0.5 * (m + ml) * np.sum(v * v, axis=-1)
    u, _ = _unit(_segment_points(body, at)[1])
    sag, tra = _segment_axes(u, _forward_axes(at, body))
    w_seg = np.stack([np.sum(omega * e, axis=-1) for e in (sag, tra, u)], axis=-1)
    inertia = m[..., None] * (body.length_m[..., None] * body.radii) ** 2
    rot = 0.5 * np.sum(inertia * w_seg**2, axis=-1)
    if np.any(body.back_load_kg > 0) and body.trunk_index >= 0:
        _add_back_load(pot, trans, _segment_points(body, pos_m)[0], pos_m, dt_s, body, centred)
    return pot, trans, rot


def _add_back_load(pot: np.ndarray, trans: np.ndarray, com: np.ndarray, pos_m: np.ndarray,
                   dt_s: float, body: BodyModel, centred: bool) -> None:
    """Add the back load (a point BACK_LOAD_OFFSET_M behind the trunk CM) to the trunk's energy."""
    k = body.trunk_index
    point = com[..., k, :] - BACK_LOAD_OFFSET_M * _forward_axes(pos_m, body)
    v = _central_diff(point, dt_s) if centred else _backward_diff(point, dt_s)
    pot[..., k] += body.back_load_kg * G_M_PER_S2 * (point if centred else _half_frames(point))[..., 2]
    trans[..., k] += 0.5 * body.back_load_kg * np.sum(v * v, axis=-1)


def _filtered_kinematics(
    motion: Motion, body: BodyModel, cutoff_hz: float, zero_phase: bool, use_rotations: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """Filtered joint positions and filtered frame-joint rotations (or None)."""
    sos = butterworth_sos(cutoff_hz, motion.fps)
    used = _used_joints(body)  # other joints do not enter the energies: copy them unfiltered
    pos = motion.positions_m.copy()
    pos[:, used] = filter_frames(motion.positions_m[:, used], sos, zero_phase=zero_phase)
    if motion.rotations is None or not use_rotations:
        return pos, None
    return pos, filter_frames(motion.rotations[:, body.frame_joint], sos, zero_phase=zero_phase)


def _used_joints(body: BodyModel) -> np.ndarray:
    """Indices of the joints that segment end points and the hip axis use."""
    used = np.any(body.proximal_weights != 0, axis=0) | np.any(body.distal_weights != 0, axis=0)
    used[list(body.hip_joints)] = True
    return np.flatnonzero(used)


def segment_energies(
    motion: Motion,
    body: BodyModel,
    *,
    cutoff_hz: float = 6.0,
    zero_phase: bool = True,
    use_rotations: bool = True,
) -> SegmentEnergies:
    """Per-frame potential, translational and rotational energy of every segment.

    Parameters
    ----------
    motion : Motion
    body : BodyModel
        Built for this motion's skeleton.
    cutoff_hz : float
        Butterworth cut-off for joint positions (6 Hz).
    zero_phase : bool
        Forward-backward filter (files) or causal (streams).
    use_rotations : bool
        Use the motion's joint rotations for angular velocity when it has them.

    Returns
    -------
    SegmentEnergies
    """
    _check_body(motion, body)
    pos, rot = _filtered_kinematics(motion, body, cutoff_hz, zero_phase, use_rotations)
    pot, trans, rot_e = kinematic_energies(pos, rot, 1.0 / motion.fps, body, centred=zero_phase)
    return SegmentEnergies(motion.t_s, pot, trans, rot_e, body.segment_names)


def _check_body(motion: Motion, body: BodyModel) -> None:
    """Raise UserError if the motion is empty or the body was built for another skeleton."""
    if motion.n_frames < 1:
        raise UserError(f"motion: expected at least one frame, got none ({motion.source})")
    if body.proximal_weights.shape[1] != len(motion.joint_names):
        raise UserError(
            f"body: expected a body built for this skeleton's {len(motion.joint_names)} joints, "
            f"got one for {body.proximal_weights.shape[1]}"
        )


# --------------------------------------------------------------------------------------------
# work and power


def check_window(window_s: float, name: str) -> float:
    """``window_s`` as a float; raise UserError naming ``name`` if it is not above 0 s."""
    if not window_s > 0:
        raise UserError(f"{name}: expected a window above 0 s, got {window_s!r}")
    return float(window_s)


def _trailing_sum(x: np.ndarray, n: int) -> np.ndarray:
    """Sum of the last n values (fewer at the start) at every index of a 1-D array."""
    c = np.cumsum(x)
    out = c.copy()
    if n < 1:
        return np.zeros_like(x)
    out[n:] = c[n:] - c[:-n]
    return out


def _window_rate(rate: np.ndarray, fps: float, window_s: float) -> np.ndarray:
    """Sum of per-frame rates over the last ``window_s`` seconds of time, divided by ``window_s``.

    Frame j's rate covers its interval (t_j - 1/fps, t_j]; the window keeps the whole frames that
    fit and the fraction of the next older one that falls inside it (as :class:`_TimeWindow`).
    """
    frames = window_s * fps
    n_full = int(np.floor(frames + 1e-9))
    frac = max(frames - n_full, 0.0)
    out = _trailing_sum(rate, n_full)
    if frac > 1e-9 and n_full < len(rate):
        out[n_full:] += frac * rate[:len(rate) - n_full]
    return out / window_s


def work_and_power(
    motion: Motion,
    body: BodyModel,
    *,
    window_s: float = 1.0,
    power_window_s: float = 0.25,
    cutoff_hz: float = 6.0,
    zero_phase: bool = True,
    use_rotations: bool = True,
) -> EnergyCurves:
    """Work w and power p (W/kg) at every frame of a clip.

    Parameters
    ----------
    motion : Motion
    body : BodyModel
        Built for this motion's skeleton; ``body.mass_kg`` is the divisor M.
    window_s : float
        Work window (1 s): w(k) = sum of |dE_s| over the frames of the last window / (M window).
    power_window_s : float
        Power window (0.25 s), same sum over a shorter window.
    cutoff_hz : float
        Butterworth cut-off on joint positions (6 Hz).
    zero_phase : bool
        Zero-phase filter (files, default) or causal (equals :class:`EnergyStream` frame by frame).
    use_rotations : bool
        Use joint rotations for angular velocity when the motion has them.

    Returns
    -------
    EnergyCurves

    Raises
    ------
    UserError
        Bad windows or cut-off (named), or a body built for another skeleton.
    """
    energies = segment_energies(motion, body, cutoff_hz=cutoff_hz, zero_phase=zero_phase,
                                use_rotations=use_rotations)
    rate = frame_rates(energies.total_j, body.mass_kg)
    return _windowed(motion.t_s, rate, motion.fps, window_s, power_window_s)


def _windowed(t_s: np.ndarray, rate: np.ndarray, fps: float, window_s: float,
              power_window_s: float) -> EnergyCurves:
    """w and p from per-frame rates: sums over the last work and power windows (seconds)."""
    window_s = check_window(window_s, "window_s")
    power_window_s = check_window(power_window_s, "power_window_s")
    return EnergyCurves(t_s, _window_rate(rate, fps, window_s), _window_rate(rate, fps, power_window_s), rate)


def looped(curves: EnergyCurves, loops: int, fps: float, *, window_s: float = 1.0,
           power_window_s: float = 0.25) -> EnergyCurves:
    """Work and power of a clip played ``loops`` times end to end.

    The clip's per-frame rates are repeated and the windows run across the seams, so w does not
    fall back to its start-of-clip ramp each time the clip restarts. The jump from the last pose
    to the first is not motion: the two frames after each seam, which have no rate of their own
    (:func:`frame_rates`), hold the clip's first real rate.

    Parameters
    ----------
    curves : EnergyCurves
        One pass of the clip, from :func:`work_and_power` (same windows).
    loops : int
        Number of passes, at least 1.
    fps : float
        The clip's frame rate.

    Returns
    -------
    EnergyCurves
        ``loops`` times as many frames, time from 0 at ``fps``.
    """
    if loops < 1:
        raise UserError(f"loops: expected a whole number from 1, found {loops!r}")
    one = curves.rate_j_per_kg
    rate = np.tile(one, loops)
    if loops > 1 and len(one) > 2:
        seam = np.arange(len(one), len(rate), len(one))
        rate[seam] = rate[seam + 1] = one[2]
    return _windowed(np.arange(len(rate)) / fps, rate, fps, window_s, power_window_s)


def frame_rates(total_j: np.ndarray, mass_kg: float) -> np.ndarray:
    """Per-frame sum over segments of |E_s(k) - E_s(k-1)| / M, zero for frames 0 and 1."""
    rate = np.zeros(total_j.shape[0])
    if total_j.shape[0] > 2:
        rate[2:] = np.sum(np.abs(np.diff(total_j[1:], axis=0)), axis=1) / mass_kg
    return rate


# --------------------------------------------------------------------------------------------
# streaming

#: Largest pre-warp angle pi * cutoff * dt (rad) of the stream filter: a frame slower than about
#: 0.38 / cutoff (64 ms at 6 Hz, a game hitch) is integrated without further pre-warping.
_MAX_WARP_RAD = 1.2


class _CausalButterworth:
    """2nd-order Butterworth low-pass integrated over each frame's own time step (any dt).

    The continuous filter y'' + sqrt(2) wc y' + wc^2 y = wc^2 x is integrated with the trapezoidal
    rule over dt, with wc pre-warped, (2 / dt) tan(pi f_c dt): at a constant dt this is exactly
    the bilinear-transform filter of :func:`butterworth_sos` (what the causal file path runs), and
    its state (y, y') stays meaningful when dt changes. Starts at the first frame's steady state.
    """

    def __init__(self, cutoff_hz: float) -> None:
        self.cutoff_hz = float(cutoff_hz)
        self._y: np.ndarray | None = None
        self._v = np.zeros(0)
        self._x = np.zeros(0)

    def step(self, x: np.ndarray, dt_s: float) -> np.ndarray:
        """Filter one frame ``x`` (any shape) that comes ``dt_s`` seconds after the previous one."""
        if self._y is None:
            self._y, self._v, self._x = x.copy(), np.zeros_like(x), x.copy()
            return x.copy()
        h = float(dt_s)
        wc = 2.0 / h * math.tan(min(math.pi * self.cutoff_hz * h, _MAX_WARP_RAD))
        hz, hw2 = h * wc / math.sqrt(2.0), (h * wc) ** 2 / 4.0
        det = 1.0 + hz + hw2
        x_sum = self._x + x
        y = ((1.0 + hz - hw2) * self._y + h * self._v + hw2 * x_sum) / det
        self._v = (-h * wc * wc * self._y + (1.0 - hz - hw2) * self._v + h * wc * wc / 2.0 * x_sum) / det
        self._y, self._x = y, x
        return y


class _TimeWindow:
    """Sum of per-frame values over the last ``window_s`` seconds of time, divided by it (O(1)).

    A frame's value covers its own interval dt_s; the oldest frame still overlapping the window
    counts for the fraction inside it. At a constant dt this is the file path's window.
    """

    def __init__(self, window_s: float, batch: tuple[int, ...]) -> None:
        self.window_s = window_s
        self._frames: collections.deque[tuple[np.ndarray, float]] = collections.deque()
        self._sum = np.zeros(batch)
        self._span_s = 0.0
        self._pushed = 0

    def push(self, value: np.ndarray, dt_s: float) -> np.ndarray:
        """Add one frame's value lasting ``dt_s``; return the window's sum / window_s."""
        self._frames.append((value, dt_s))
        self._sum = self._sum + value
        self._span_s += dt_s
        while len(self._frames) > 1 and self._span_s - self._frames[0][1] >= self.window_s:
            old, old_dt = self._frames.popleft()
            self._sum = self._sum - old
            self._span_s -= old_dt
        self._pushed += 1
        if self._pushed % 4096 == 0:  # re-sum now and then so rounding cannot drift
            self._sum = np.sum([v for v, _ in self._frames], axis=0)
            self._span_s = math.fsum(d for _, d in self._frames)
        total = self._sum
        if self._span_s > self.window_s:
            old, old_dt = self._frames[0]
            total = total - old * ((self._span_s - self.window_s) / old_dt)
        return total / self.window_s


class EnergyStream:
    """Causal, frame-by-frame work and power for a live skeleton (O(1) per frame).

    Each frame brings its own ``dt_s`` (games have variable frame times): the low-pass filter is
    integrated over that step and the windows are measured in seconds of time, so the work does
    not depend on the frame rate. At a constant ``dt_s = 1 / fps`` it gives the same numbers as
    ``work_and_power(..., zero_phase=False)`` on the same frames.

    Parameters
    ----------
    body : BodyModel
    fps : float
        Nominal frame rate: the cut-off is checked against its Nyquist frequency.
    window_s, power_window_s, cutoff_hz : float
        As in :func:`work_and_power`.

    Raises
    ------
    UserError
        Bad fps, windows or cut-off (named).

    Examples
    --------
    >>> stream = EnergyStream(body, fps=60)                          # doctest: +SKIP
    >>> w_per_kg, p_per_kg = stream.step(joint_positions_m, 1 / 60)  # doctest: +SKIP
    """

    def __init__(self, body: BodyModel, fps: float, *, window_s: float = 1.0,
                 power_window_s: float = 0.25, cutoff_hz: float = 6.0) -> None:
        if not fps > 0:
            raise UserError(f"fps: expected a positive frame rate, got {fps!r}")
        self.body = body
        self.fps = float(fps)
        butterworth_sos(cutoff_hz, self.fps)  # checks the cut-off against the nominal rate
        self._filter = _CausalButterworth(cutoff_hz)
        self._batch = np.shape(body.mass_kg)  # () for one character, (N,) for a crowd
        self._work = _TimeWindow(check_window(window_s, "window_s"), self._batch)
        self._power = _TimeWindow(check_window(power_window_s, "power_window_s"), self._batch)
        self._frame = 0
        self._with_rotations: bool | None = None
        self._prev: tuple[np.ndarray, np.ndarray | None] | None = None
        self._prev_e: np.ndarray | None = None

    def step(self, joint_positions_m: np.ndarray, dt_s: float,
             rotations: np.ndarray | None = None) -> tuple[float, float]:
        """Advance one frame.

        Parameters
        ----------
        joint_positions_m : ndarray, shape (J, 3)
            World joint positions, metres, Z up.
        dt_s : float
            Time since the previous frame, seconds (> 0; used for the filter, velocities and
            the windows; it may vary from frame to frame).
        rotations : ndarray, shape (J, 3, 3), optional
            World joint rotations; without them spin about a segment's long axis is not seen.
            Give them on every frame or on none.

        Returns
        -------
        w_per_kg, p_per_kg : float

        Raises
        ------
        UserError
            Wrong shapes, dt_s <= 0, or rotations given on some frames only.
        """
        w, p = self._advance(joint_positions_m, dt_s, rotations)
        return float(w), float(p)

    def _advance(self, joint_positions_m: np.ndarray, dt_s: float,
                 rotations: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """One frame for one character or a crowd: filter, energies, window sums."""
        pos, rot = self._check_frame(joint_positions_m, dt_s, rotations)
        parts = [pos.reshape(*self._batch, -1)]
        if rot is not None:
            parts.append(rot[..., self.body.frame_joint, :, :].reshape(*self._batch, -1))
        flat = self._filter.step(np.concatenate(parts, axis=-1), dt_s)
        n_pos = parts[0].shape[-1]
        cur = (flat[..., :n_pos].reshape(pos.shape),
               None if rot is None else flat[..., n_pos:].reshape(*self._batch, -1, 3, 3))
        energy = self._energy(cur, dt_s)
        rate = np.zeros(self._batch)
        if self._frame >= 2:
            rate = np.sum(np.abs(energy - self._prev_e), axis=-1) / self.body.mass_kg
        self._prev, self._prev_e = cur, energy
        self._frame += 1
        return self._work.push(rate, float(dt_s)), self._power.push(rate, float(dt_s))

    def _check_frame(self, joint_positions_m: np.ndarray, dt_s: float,
                     rotations: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """Validate one frame's inputs; return them as float arrays."""
        n_joints = self.body.proximal_weights.shape[1]
        pos = np.asarray(joint_positions_m, dtype=float)
        if pos.shape != (*self._batch, n_joints, 3):
            raise UserError(
                f"joint_positions_m: expected shape {(*self._batch, n_joints, 3)}, got {pos.shape}")
        if not dt_s > 0:
            raise UserError(f"dt_s: expected a positive frame interval in seconds, got {dt_s!r}")
        with_rot = rotations is not None
        if self._with_rotations is not None and with_rot != self._with_rotations:
            raise UserError("rotations: expected on every frame or on none, got them on some frames only")
        self._with_rotations = with_rot
        if rotations is None:
            return pos, None
        rot = np.asarray(rotations, dtype=float)
        if rot.shape != (*self._batch, n_joints, 3, 3):
            raise UserError(f"rotations: expected shape {(*self._batch, n_joints, 3, 3)}, got {rot.shape}")
        return pos, rot

    def _energy(self, cur: tuple[np.ndarray, np.ndarray | None], dt_s: float) -> np.ndarray:
        """Total energy per segment ([N,] S) at this frame, from the previous and current states."""
        prev = self._prev if self._prev is not None else cur
        pos = np.stack([prev[0], cur[0]])
        rot = None if cur[1] is None or prev[1] is None else np.stack([prev[1], cur[1]])
        pot, trans, rot_e = kinematic_energies(pos, rot, dt_s, self.body)
        k = 0 if self._prev is None else 1
        return pot[k] + trans[k] + rot_e[k]


class EnergyCrowd(EnergyStream):
    """Causal work and power for N characters on one skeleton, vectorised over characters.

    Each character keeps its own body (mass, bone lengths, loads); every frame costs about what
    one :class:`EnergyStream` step costs, whatever N. Character i gets exactly the numbers of its
    own ``EnergyStream``.

    Parameters
    ----------
    bodies : sequence of BodyModel
        One body per character, all built on the same skeleton and mapping.
    fps, window_s, power_window_s, cutoff_hz : float
        As in :class:`EnergyStream`.
    """

    def __init__(self, bodies: Sequence[BodyModel], fps: float, *, window_s: float = 1.0,
                 power_window_s: float = 0.25, cutoff_hz: float = 6.0) -> None:
        super().__init__(stack_bodies(bodies), fps, window_s=window_s, power_window_s=power_window_s,
                         cutoff_hz=cutoff_hz)

    def step(self, joint_positions_m: np.ndarray, dt_s: float,  # type: ignore[override]  # (N, J, 3)
             rotations: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Advance every character one frame.

        Parameters
        ----------
        joint_positions_m : ndarray, shape (N, J, 3)
            World joint positions of every character, metres, Z up.
        dt_s : float
            Time since the previous frame, seconds.
        rotations : ndarray, shape (N, J, 3, 3), optional
            World joint rotations (every frame or none).

        Returns
        -------
        w_per_kg, p_per_kg : ndarray, shape (N,)
        """
        return self._advance(joint_positions_m, dt_s, rotations)
