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
  causal for streams. Both start from the steady state of the first frame.
* Streams run on a fixed internal tick (``tick_hz``, the nominal frame rate by default), not on
  the game's frames: each frame's positions (and rotations) are interpolated to the ticks that fall
  since the previous frame, by the parabola through the last three frames (exact for a glide or
  a free fall; a straight line after a frame less than a quarter as long as the next), and the
  filter, differences and energies run at the tick's constant step with fixed coefficients. A
  filter re-tuned from each frame's own dt changes its lag from frame to frame, and a moving body
  then gains false velocity changes (a 3.4 m/s glide read 12.3 W/kg at 30 fps with +-30 % jitter;
  SCIENCE_NOTES "Live work on a fixed internal tick"). At a constant ``dt_s = 1 / tick_hz`` the
  ticks are the frames: exactly the causal file filter.
* Consistent differences: the energy of frame k is taken at the half frame t(k-1/2), with the
  positions averaged over frames k-1 and k and the velocities (x(k) - x(k-1)) / dt, the central
  difference about that instant. Kinetic and potential energy therefore refer to the same
  instant (a freely falling body does no work; a backward velocity with the frame's own height
  would make it do g^2 dt / 2 W/kg). Angular velocity comes from consecutive segment rotations,
  ``log(R(k) R(k-1)^T) / dt``; without rotations (plain positions) it comes from the turn of the
  segment's long axis, so spin about the long axis is not seen.
* Windows are measured in seconds of time, not in frames: a frame's |dE| is spread over its own
  interval and the window keeps the part of it that falls in the last ``window_s``. A stream
  fed at 30, 60 or 120 fps, or with jittering frame times, measures the same work.
* Segment frame: long axis from the proximal to the distal end; sagittal (antero-posterior) axis is
  the body's forward direction (from the hip joints and the vertical) made orthogonal to the long
  axis (the vertical when the segment points forward, as a foot does); transverse completes it.
* The first two frames contribute no work (the first has no velocity).
* Loads: point masses at the hand CMs, and on the back :data:`~effortface.synth.segments.BACK_LOAD_OFFSET_M`
  behind the trunk CM, added to that segment's energy. M stays the character's own mass.

Paths: :func:`work_and_power` for a whole clip (zero-phase or causal), :class:`EnergyStream` one
frame at a time (equal to the causal whole-clip path), :class:`EnergyCrowd` for N characters at once.
numpy only (the runtime imports this module; the filters are :mod:`effortface.synth.iir`).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.synth import iir
from effortface.synth.motion import Motion
from effortface.synth.segments import BACK_LOAD_OFFSET_M, BodyModel, stack_bodies

#: Gravitational acceleration, m/s^2.
G_M_PER_S2 = 9.81
_EZ = np.array([0.0, 0.0, 1.0])
#: defaults of :func:`work_and_power` and the streams: work's trailing window (s), power's (s) and
#: the energy filter's cutoff (Hz)
WORK_WINDOW_S, POWER_WINDOW_S, CUTOFF_HZ = 1.0, 0.25, 6.0


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
    return iir.butterworth_lowpass_sos(order, cutoff_hz, fps)


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
    return np.moveaxis(_filter_time_last(np.moveaxis(np.asarray(x), 0, -1), sos, zero_phase), -1, 0)


def _filter_time_last(x: Any, sos: np.ndarray, zero_phase: bool) -> np.ndarray:
    """:func:`filter_frames` along the last axis of ``x`` (or of the stack of a sequence of (c_i, T)
    arrays, see :func:`effortface.synth.iir.sosfilt`)."""
    if not zero_phase:
        return iir.sosfilt(sos, x)
    n_frames = x.shape[-1] if isinstance(x, np.ndarray) else np.shape(x[0])[-1]
    return iir.sosfiltfilt(sos, x, max(min(3 * (2 * len(sos) + 1), n_frames - 1), 0))  # scipy's padding


# --------------------------------------------------------------------------------------------
# kinematics -> energies (shared by the whole-clip path and the stream)
#
# Components first: a vector quantity is an array (3, S, M) (x, y, z; segments; M frames of a clip or
# characters of a crowd), a rotation (3, 3, S, M), a scalar (S, M). Dot and cross products are then
# a few whole-array operations (a reduction over a last axis of length 3 costs over 10x more).


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the leading (component) axis."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the leading (component) axis."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors over the leading axis and the norms (zero vectors stay zero)."""
    n = np.sqrt(_dot(v, v))
    return np.divide(v, n, out=np.zeros_like(v), where=n > 1e-12), n


def _rotation_vector(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vector (rad, (3, ...)) of ``b @ a^T`` for rotations a (previous) and b, (3, 3, ...)."""

    def rel(i: int, k: int) -> np.ndarray:  # (b @ a^T)[i, k]
        return _dot(b[i], a[k])

    vee = 0.5 * np.stack([rel(2, 1) - rel(1, 2), rel(0, 2) - rel(2, 0), rel(1, 0) - rel(0, 1)])
    axis, sin_angle = _unit(vee)
    cos_angle = 0.5 * (rel(0, 0) + rel(1, 1) + rel(2, 2) - 1.0)
    return axis * np.arctan2(sin_angle, cos_angle)


def _axis_turn(u_prev: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) turning unit vector u_prev onto u (no spin about the axis)."""
    axis, sin_angle = _unit(_cross(u_prev, u))
    return axis * np.arctan2(sin_angle, _dot(u_prev, u))


def _forward_axes(hip_line: np.ndarray) -> np.ndarray:
    """Body forward direction (3, M) from the left-minus-right hip vector (3, M): hip line x
    vertical (the x axis if degenerate)."""
    fwd, norm = _unit(np.stack([hip_line[1], -hip_line[0], np.zeros_like(hip_line[0])]))
    fwd[:, norm < 1e-9] = np.array([1.0, 0.0, 0.0])[:, None]
    return fwd


def _segment_axes(u: np.ndarray, fwd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sagittal and transverse unit axes (3, S, M) for long axes u (3, S, M), forward (3, M)."""
    fwd = fwd[:, None, :]
    a, norm = _unit(fwd - _dot(fwd, u) * u)
    up = _unit(np.stack([-u[2] * u[0], -u[2] * u[1], 1.0 - u[2] * u[2]]))[0]  # vertical minus its u part
    a = np.where(norm < 0.3, up, a)
    return a, _cross(u, a)


def _half_frames(x: np.ndarray) -> np.ndarray:
    """Values at the half frames t(k-1/2): means of frames k-1 and k along the last axis (frame 0 kept)."""
    mid = x.copy()
    mid[..., 1:] = 0.5 * (x[..., 1:] + x[..., :-1])
    return mid


def _backward_diff(x: np.ndarray, dt_s: float) -> np.ndarray:
    """(x[k] - x[k-1]) / dt along the last axis, with zero for the first frame."""
    d = np.zeros_like(x)
    d[..., 1:] = (x[..., 1:] - x[..., :-1]) / dt_s
    return d


def _central_diff(x: np.ndarray, dt_s: float) -> np.ndarray:
    """(x[k+1] - x[k-1]) / (2 dt) along the last axis; one-sided at the two ends, zero for one frame."""
    if x.shape[-1] < 2:
        return np.zeros_like(x)
    return np.gradient(x, dt_s, axis=-1)


def _central_turn(turn: Callable[[np.ndarray, np.ndarray], np.ndarray], a: np.ndarray,
                  dt_s: float) -> np.ndarray:
    """Angular velocity at every frame (last axis) from a frame-pair turn function, central where possible."""
    if a.shape[-1] < 2:
        return turn(a, a)  # no turn: zeros of the right shape
    return np.concatenate([turn(a[..., :1], a[..., 1:2]), 0.5 * turn(a[..., :-2], a[..., 2:]),
                           turn(a[..., -2:-1], a[..., -1:])], axis=-1) / dt_s


@dataclasses.dataclass(frozen=True)
class _Layout:
    """A body's numbers arranged for the components-first energies: per-segment values (S, 1) for
    one body, (S, N) for N stacked bodies, and the matrix mixing joints into end points."""

    mixer: np.ndarray        # (6 S + 6, 3 J): flat joint positions -> proximal, distal ends, hips
    n_segments: int
    com_frac: np.ndarray
    mass_kg: np.ndarray       # segment mass, loads included
    segment_mass_kg: np.ndarray
    inertia: np.ndarray       # (3, S, .): m (L r_axis)^2 about the sagittal, transverse, long axes
    back_load_kg: np.ndarray  # () or (N,)
    trunk_index: int

    @classmethod
    def of(cls, body: BodyModel) -> _Layout:
        """The layout of one body, or of bodies stacked by :func:`~effortface.synth.segments.stack_bodies`."""
        n_seg, n_joints = body.proximal_weights.shape
        weights = np.concatenate([body.proximal_weights, body.distal_weights])  # (2 S, J)
        mixer = np.zeros((6 * n_seg + 6, n_joints, 3))  # rows (end, component, segment), then hips
        for c in range(3):
            for e in range(2):
                mixer[(3 * e + c) * n_seg:(3 * e + c + 1) * n_seg, :, c] = weights[e * n_seg:(e + 1) * n_seg]
            for h in range(2):
                mixer[6 * n_seg + 3 * h + c, body.hip_joints[h], c] = 1.0

        def seg(x: Any) -> np.ndarray:  # (S,) -> (S, 1); stacked (N, S) -> (S, N)
            x = np.asarray(x, dtype=float)
            return x[:, None] if x.ndim == 1 else x.T

        radii = np.asarray(body.radii, dtype=float)
        radii = radii.T[:, :, None] if radii.ndim == 2 else radii.transpose(2, 1, 0)  # (3, S, .)
        m = seg(body.segment_mass_kg)
        inertia = m[None] * (seg(body.length_m)[None] * radii) ** 2
        return cls(mixer.reshape(len(mixer), -1), n_seg, seg(body.com_frac), m + seg(body.load_kg), m,
                   inertia, np.asarray(body.back_load_kg, dtype=float), body.trunk_index)

    def points(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment CMs and long-axis vectors (distal - proximal end), each (3, S, M), and the
        left-minus-right hip vector (3, M), of joint positions (3 J, M) ordered (joint, axis): one
        matrix product."""
        n = self.n_segments
        ends = self.mixer @ pos
        prox = ends[:3 * n].reshape(3, n, -1)
        limb = ends[3 * n:6 * n].reshape(3, n, -1) - prox
        return prox + self.com_frac * limb, limb, ends[6 * n:6 * n + 3] - ends[6 * n + 3:]

    def energies(self, com: np.ndarray, u: np.ndarray, hip_line: np.ndarray, v: np.ndarray,
                 omega: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Potential, translational and rotational energy (S, M) from the CMs, unit long axes and hip
        line at one instant and the CM and angular velocities about it."""
        pot = self.mass_kg * G_M_PER_S2 * com[2]
        trans = 0.5 * self.mass_kg * _dot(v, v)
        sag, tra = _segment_axes(u, _forward_axes(hip_line))
        i_sag, i_tra, i_long = self.inertia
        w_sag, w_tra, w_long = _dot(omega, sag), _dot(omega, tra), _dot(omega, u)
        return pot, trans, 0.5 * (i_sag * w_sag**2 + i_tra * w_tra**2 + i_long * w_long**2)

    @property
    def has_back_load(self) -> bool:
        """Whether a back load is carried (and there is a trunk to carry it)."""
        return self.trunk_index >= 0 and bool(np.any(self.back_load_kg > 0))

    def back_load_point(self, com: np.ndarray, hip_line: np.ndarray) -> np.ndarray:
        """The back load's position (3, M): BACK_LOAD_OFFSET_M behind the trunk CM."""
        return com[:, self.trunk_index] - BACK_LOAD_OFFSET_M * _forward_axes(hip_line)

    def add_back_load(self, pot: np.ndarray, trans: np.ndarray, point: np.ndarray, v: np.ndarray) -> None:
        """Add the back load's energy (its position and velocity at the instant) to the trunk's."""
        k = self.trunk_index
        pot[k] += self.back_load_kg * G_M_PER_S2 * point[2]
        trans[k] += 0.5 * self.back_load_kg * _dot(v, v)


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
    pos_m : ndarray, shape (T, J, 3)
        Filtered joint positions, metres, Z up.
    frame_rot : ndarray, shape (T, S, 3, 3), or None
        Filtered rotation of each segment's frame joint, or None (long-axis turn only).
    dt_s : float
        Frame interval in seconds.
    body : BodyModel
        The body (one character).
    centred : bool
        The scheme, see above.

    Returns
    -------
    potential_j, translational_j, rotational_j : ndarray, shape (T, S)
        Loads are included in their segment's energy.
    """
    pos = np.asarray(pos_m, dtype=float).reshape(len(pos_m), -1).T
    rot = None if frame_rot is None else np.asarray(frame_rot, dtype=float).reshape(len(frame_rot), -1).T
    pot, trans, rot_e = _time_last_energies(pos, rot, dt_s, body, centred)
    return pot.T, trans.T, rot_e.T


def _time_last_energies(pos: np.ndarray, rot: np.ndarray | None, dt_s: float, body: BodyModel,
                        centred: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kinematic_energies` on time-last arrays: positions (3 J, T) ordered (joint, axis),
    frame rotations (9 S, T) ordered (segment, row, column) or None; energies (S, T)."""
    layout = _Layout.of(body)
    com, limb, hip_line = layout.points(pos)
    if rot is not None:
        rot = rot.reshape(layout.n_segments, 3, 3, -1).transpose(1, 2, 0, 3)  # (3, 3, S, T), a view
    u = _unit(limb)[0]
    if centred:
        v = _central_diff(com, dt_s)
        omega = _central_turn(_rotation_vector, rot, dt_s) if rot is not None else _central_turn(_axis_turn, u, dt_s)
        at = (com, u, hip_line)
    else:  # the half frames: positions averaged (limbs too: the mixing is linear), velocities about them
        v = _backward_diff(com, dt_s)
        omega = np.zeros(com.shape)
        omega[..., 1:] = (_rotation_vector(rot[..., :-1], rot[..., 1:]) if rot is not None
                          else _axis_turn(u[..., :-1], u[..., 1:])) / dt_s
        at = (_half_frames(com), _unit(_half_frames(limb))[0], _half_frames(hip_line))
    pot, trans, rot_e = layout.energies(*at, v, omega)
    if layout.has_back_load:
        point = layout.back_load_point(com, hip_line)
        v_point = _central_diff(point, dt_s) if centred else _backward_diff(point, dt_s)
        layout.add_back_load(pot, trans, point if centred else _half_frames(point), v_point)
    return pot, trans, rot_e


def _on_used_joints(body: BodyModel) -> tuple[BodyModel, np.ndarray]:
    """The body with its end-point weights on the joints they use only, and those joints' indices.

    The energies see only these joints (the other ones' weights are zero), so filtering and
    mixing the rest would be wasted work.
    """
    used = _used_joints(body)
    at = {int(j): i for i, j in enumerate(used)}
    return dataclasses.replace(body, proximal_weights=body.proximal_weights[:, used],
                               distal_weights=body.distal_weights[:, used],
                               hip_joints=(at[body.hip_joints[0]], at[body.hip_joints[1]])), used


def _filtered_kinematics(
    motion: Motion, used: np.ndarray, frame_joint: np.ndarray, cutoff_hz: float, zero_phase: bool,
    use_rotations: bool,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Filtered positions of the ``used`` joints (3 U, T) and filtered frame-joint rotations (9 S, T)
    or None, time last (each joint's values go straight into the filter's buffer)."""
    sos = butterworth_sos(cutoff_hz, motion.fps)
    pos = _filter_time_last([motion.positions_m[:, j].T for j in used], sos, zero_phase)
    if motion.rotations is None or not use_rotations:
        return pos, None
    n_frames = motion.n_frames
    rot = [motion.rotations[:, j].reshape(n_frames, 9).T for j in frame_joint]
    return pos, _filter_time_last(rot, sos, zero_phase)


def _used_joints(body: BodyModel) -> np.ndarray:
    """Indices of the joints that segment end points and the hip axis use."""
    used = np.any(body.proximal_weights != 0, axis=0) | np.any(body.distal_weights != 0, axis=0)
    used[list(body.hip_joints)] = True
    return np.flatnonzero(used)


def segment_energies(
    motion: Motion,
    body: BodyModel,
    *,
    cutoff_hz: float = CUTOFF_HZ,
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
    on_used, used = _on_used_joints(body)  # the other joints do not enter the energies
    pos, rot = _filtered_kinematics(motion, used, body.frame_joint, cutoff_hz, zero_phase, use_rotations)
    pot, trans, rot_e = _time_last_energies(pos, rot, 1.0 / motion.fps, on_used, zero_phase)
    return SegmentEnergies(motion.t_s, pot.T, trans.T, rot_e.T, body.segment_names)


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
    window_s: float = WORK_WINDOW_S,
    power_window_s: float = POWER_WINDOW_S,
    cutoff_hz: float = CUTOFF_HZ,
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


def looped(curves: EnergyCurves, loops: int, fps: float, *, window_s: float = WORK_WINDOW_S,
           power_window_s: float = POWER_WINDOW_S) -> EnergyCurves:
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


#: Quadratic interpolation needs the previous frame interval to be at least this share of the
#: current one; after a much shorter frame the parabola would amplify noise, so a line is used.
_MIN_QUADRATIC_RATIO = 0.25


class _TickResampler:
    """Frames at any times -> samples on a fixed tick grid t = k / tick_hz (causal).

    Each new frame at time t_n releases the ticks in (t_(n-1), t_n]; a tick's value is the
    parabola through frames n-2, n-1 and n (Lagrange form: exact for motion quadratic in time,
    such as a glide or a free fall), a straight line through frames n-1 and n when only two frames
    are known or the previous interval is under :data:`_MIN_QUADRATIC_RATIO` of the current one.
    A tick within a millionth of a tick of a frame takes that frame's values exactly, so at a
    constant ``dt_s = 1 / tick_hz`` every frame is one tick and nothing is interpolated.
    """

    def __init__(self, tick_hz: float) -> None:
        self.tick_s = 1.0 / float(tick_hz)
        self._frames: collections.deque[tuple[float, np.ndarray]] = collections.deque(maxlen=3)
        self._t_s = 0.0
        self._next_tick = 0

    def push(self, x: np.ndarray, dt_s: float) -> list[np.ndarray]:
        """Add a frame ``dt_s`` after the previous one (ignored for the first); return its ticks."""
        if self._frames:
            self._t_s += float(dt_s)
        self._frames.append((self._t_s, x))
        tol_s = 1e-6 * self.tick_s
        out = []
        while self._next_tick * self.tick_s <= self._t_s + tol_s:
            out.append(self._value(self._next_tick * self.tick_s, tol_s))
            self._next_tick += 1
        return out

    def _value(self, t_s: float, tol_s: float) -> np.ndarray:
        """The interpolated value at ``t_s`` (within the last frame interval)."""
        frames = self._frames
        t_c, x_c = frames[-1]
        if abs(t_s - t_c) <= tol_s or len(frames) == 1:
            return x_c
        t_b, x_b = frames[-2]
        if len(frames) == 3 and frames[1][0] - frames[0][0] >= _MIN_QUADRATIC_RATIO * (t_c - t_b):
            t_a, x_a = frames[0]
            l_a = (t_s - t_b) * (t_s - t_c) / ((t_a - t_b) * (t_a - t_c))
            l_b = (t_s - t_a) * (t_s - t_c) / ((t_b - t_a) * (t_b - t_c))
            l_c = (t_s - t_a) * (t_s - t_b) / ((t_c - t_a) * (t_c - t_b))
            return l_a * x_a + l_b * x_b + l_c * x_c
        f = (t_s - t_b) / (t_c - t_b)
        return (1.0 - f) * x_b + f * x_c


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
    """Causal, frame-by-frame work and power for a live skeleton (O(1) per tick).

    Each frame brings its own ``dt_s`` (games have variable frame times). The frames are resampled
    to a fixed internal tick (:class:`_TickResampler`: the parabola through the last three frames)
    and the filter, differences and windows run on the ticks with fixed coefficients, so the work
    of a motion does not depend on the frame times. A step returns the values at the latest tick
    at or before its frame (the previous values when no tick fell inside a short frame). At a
    constant ``dt_s = 1 / tick_hz`` it gives the same numbers as
    ``work_and_power(..., zero_phase=False)`` on the same frames.

    Parameters
    ----------
    body : BodyModel
    fps : float
        Nominal frame rate: the internal tick rate unless ``tick_hz`` is given; the cut-off is
        checked against the tick's Nyquist frequency.
    window_s, power_window_s, cutoff_hz : float
        As in :func:`work_and_power`.
    tick_hz : float, optional
        Internal tick rate (default ``fps``). A step costs one tick per 1 / tick_hz of game time.

    Raises
    ------
    UserError
        Bad fps, windows or cut-off (named).

    Examples
    --------
    >>> stream = EnergyStream(body, fps=60)                          # doctest: +SKIP
    >>> w_per_kg, p_per_kg = stream.step(joint_positions_m, 1 / 60)  # doctest: +SKIP
    """

    def __init__(self, body: BodyModel, fps: float, *, window_s: float = WORK_WINDOW_S,
                 power_window_s: float = POWER_WINDOW_S, cutoff_hz: float = CUTOFF_HZ,
                 tick_hz: float | None = None) -> None:
        if not fps > 0:
            raise UserError(f"fps: expected a positive frame rate, got {fps!r}")
        if tick_hz is not None and not tick_hz > 0:
            raise UserError(f"tick_hz: expected a positive tick rate, got {tick_hz!r}")
        self.body = body
        self.fps = float(fps)
        self.tick_hz = float(tick_hz) if tick_hz is not None else self.fps
        butterworth_sos(cutoff_hz, self.tick_hz)  # checks the cut-off against the tick rate
        self._filter = _CausalButterworth(cutoff_hz)
        self._ticks = _TickResampler(self.tick_hz)
        self._last = (np.zeros(np.shape(body.mass_kg)), np.zeros(np.shape(body.mass_kg)))
        self._batch = np.shape(body.mass_kg)  # () for one character, (N,) for a crowd
        self._work = _TimeWindow(check_window(window_s, "window_s"), self._batch)
        self._power = _TimeWindow(check_window(power_window_s, "power_window_s"), self._batch)
        self._frame = 0
        self._with_rotations: bool | None = None
        on_used, self._used = _on_used_joints(body)  # the joints the energies see
        self._layout = _Layout.of(on_used)
        #: the previous frame's CMs, unit long axes, limbs, hip line and back-load point (3, S, M)
        #: or (3, M), and its frame rotations (3, 3, S, M)
        self._prev: tuple[np.ndarray, ...] | None = None
        self._prev_rot: np.ndarray | None = None
        self._prev_e: np.ndarray | None = None

    def step(self, joint_positions_m: np.ndarray, dt_s: float,
             rotations: np.ndarray | None = None) -> tuple[float, float]:
        """Advance one frame.

        Parameters
        ----------
        joint_positions_m : ndarray, shape (J, 3)
            World joint positions, metres, Z up.
        dt_s : float
            Time since the previous frame, seconds (> 0; it places the frame on the time line
            the ticks are interpolated on; it may vary from frame to frame).
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
        """One frame for one character or a crowd: resample to ticks; per tick filter, energies, windows."""
        pos, rot = self._check_frame(joint_positions_m, dt_s, rotations)
        pos = pos[..., self._used, :]
        parts = [pos.reshape(*self._batch, -1)]
        if rot is not None:
            parts.append(rot[..., self.body.frame_joint, :, :].reshape(*self._batch, -1))
        raw = np.concatenate(parts, axis=-1) if len(parts) > 1 else parts[0]
        for sample in self._ticks.push(raw, float(dt_s)):
            self._last = self._tick(sample, pos.shape, parts[0].shape[-1], rot is not None)
        return self._last

    def _tick(self, sample: np.ndarray, pos_shape: tuple[int, ...], n_pos: int,
              with_rot: bool) -> tuple[np.ndarray, np.ndarray]:
        """One internal tick: fixed-step filter, energies at the half tick, window sums."""
        h = self._ticks.tick_s
        flat = self._filter.step(sample, h)
        cur = (flat[..., :n_pos].reshape(pos_shape),
               flat[..., n_pos:].reshape(*self._batch, -1, 3, 3) if with_rot else None)
        energy = self._energy(cur, h)  # (S, characters)
        rate = np.zeros(self._batch)
        if self._frame >= 2:
            rate = np.sum(np.abs(energy - self._prev_e), axis=0).reshape(self._batch) / self.body.mass_kg
        self._prev_e = energy
        self._frame += 1
        return self._work.push(rate, h), self._power.push(rate, h)

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
        """Total energy per segment (S, characters) at the half frame before this one (at this frame
        for the first): :func:`kinematic_energies`' causal scheme, from the previous frame's values."""
        pos, rot = cur
        n = int(np.prod(self._batch, dtype=int))  # characters: 1 for a single stream
        layout = self._layout
        com, limb, hip_line = layout.points(pos.reshape(n, -1).T)
        u = _unit(limb)[0]
        point = layout.back_load_point(com, hip_line) if layout.has_back_load else hip_line
        if rot is not None:
            rot = np.ascontiguousarray(rot.reshape(n, -1, 3, 3).transpose(2, 3, 1, 0))
        prev = self._prev if self._prev is not None else (com, u, limb, hip_line, point)
        prev_rot = self._prev_rot if self._prev is not None else rot
        v = (com - prev[0]) / dt_s
        turn = _axis_turn(prev[1], u) if rot is None or prev_rot is None else _rotation_vector(prev_rot, rot)
        mid = [0.5 * (x + x_prev) for x, x_prev in zip((com, limb, hip_line, point), (prev[0], *prev[2:]))]
        pot, trans, rot_e = layout.energies(mid[0], _unit(mid[1])[0], mid[2], v, turn / dt_s)
        if layout.has_back_load:
            layout.add_back_load(pot, trans, mid[3], (point - prev[4]) / dt_s)
        self._prev, self._prev_rot = (com, u, limb, hip_line, point), rot
        return pot + trans + rot_e


class EnergyCrowd(EnergyStream):
    """Causal work and power for N characters on one skeleton, vectorised over characters.

    Each character keeps its own body (mass, bone lengths, loads); every frame costs about what
    one :class:`EnergyStream` step costs, whatever N. Character i gets exactly the numbers of its
    own ``EnergyStream``.

    Parameters
    ----------
    bodies : sequence of BodyModel
        One body per character, all built on the same skeleton and mapping.
    fps, window_s, power_window_s, cutoff_hz, tick_hz : float
        As in :class:`EnergyStream`.
    """

    def __init__(self, bodies: Sequence[BodyModel], fps: float, *, window_s: float = WORK_WINDOW_S,
                 power_window_s: float = POWER_WINDOW_S, cutoff_hz: float = CUTOFF_HZ,
                 tick_hz: float | None = None) -> None:
        super().__init__(stack_bodies(bodies), fps, window_s=window_s, power_window_s=power_window_s,
                         cutoff_hz=cutoff_hz, tick_hz=tick_hz)

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
