"""Heart rate, phases and the curve editor under the video, on one session-time axis (pyqtgraph).

:class:`QtTimeline` views an :class:`~effortface.annotate.annotate_session.AnnotateSession`:

- top plot: heart rate (valid samples; gaps where the strap lost contact) with the exercise
  phases shaded and named (a name elided to its band's width on screen, in full in its tooltip);
- bottom plot, the curve editor: the rater's own curve of the current blendshape (their other
  blendshapes thinner, each in its own colour, each shown or hidden with :meth:`QtTimeline.set_shown`),
  its key-frames as points. Click a key to select it (and go to its frame), Shift+click to add keys
  to a selection (moved and scaled together by the editor's keys, one undo step), drag a key to
  move it in time and weight (one undo step, snapped to a recorded frame), click empty space to go
  to that time, double-click to add a key there; Delete removes the selected key; moving to another
  frame clears a one-key selection;
- the machine guide (``machine/face_landmarker.csv``): each blendshape's machine curve dashed under the
  rater's own curves (shown or hidden per blendshape with :meth:`QtTimeline.set_machine_shown`), and the
  frames where the machine found no face shaded grey and labelled "no face";
- keys the rater accepted from the machine and has not edited are grey diamonds, and the curve is grey
  where its nearest key is one of them (the machine's colour, :data:`MACHINE_KEY_COLOUR`); the rater's
  own keys (typed or edited) and their stretches are in the curve's colour;
- zoom: :meth:`QtTimeline.zoom` (the editor binds + and -) about the cursor, :meth:`frame_all` (F);
  the view never shows time before the session's start nor after its end;
- a cursor line at the current frame's time in both plots; dragging it scrubs the video; the view
  follows the cursor (:attr:`QtTimeline.follow`: ``"page"`` turns the page when the cursor leaves the
  view, ``"centre"`` keeps it in the middle, ``"off"`` leaves the view alone).

Everything is written back through the model's methods (the rule: a view writes back only through model methods and keeps widget state only); the widget keeps only the
selection and the drag preview.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.annotate.annotate_session import AnnotateSession

#: one colour per blendshape, in the set's order (the current one is drawn thick, the others thin)
CURVE_COLOURS = ("#1f5fbf", "#d0601a", "#2a9d3a", "#9a3fb5", "#8c564b", "#c0306a")
_KEY_BRUSH = pg.mkBrush("#1f5fbf")
_SELECTED_BRUSH = pg.mkBrush("#e07000")
_PHASE_BRUSHES = (pg.mkBrush(90, 140, 220, 40), pg.mkBrush(230, 150, 60, 40))
_NO_FACE_BRUSH = pg.mkBrush(120, 120, 120, 60)
_MACHINE_BRUSH = pg.mkBrush("#6e6e6e")
#: keys accepted from the machine (not edited) are drawn in the machine's colour, as diamonds
MACHINE_KEY_COLOUR = "#6e6e6e"
#: width of both plots' left axes (their time axes line up; the HR title fits)
LEFT_AXIS_PX = 48
#: how the view follows the play head
FOLLOW_MODES = ("page", "centre", "off")
#: "no face" labels drawn at most (every stretch is shaded)
_MAX_NO_FACE_LABELS = 30


class _ClickViewBox(pg.ViewBox):
    """A ViewBox that reports left clicks and double-clicks on empty space in data coordinates."""

    def __init__(self) -> None:
        super().__init__()
        self.on_click: Callable[[float, float], None] | None = None
        self.on_double_click: Callable[[float, float], None] | None = None

    def mouseClickEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph override
        if ev.button() != QtCore.Qt.MouseButton.LeftButton:
            super().mouseClickEvent(ev)
            return
        ev.accept()
        p = self.mapSceneToView(ev.scenePos())
        handler = self.on_double_click if ev.double() else self.on_click
        if handler is not None:
            handler(p.x(), p.y())


def key_size(n_keys: int) -> int:
    """Key dots' diameter in pixels: small, and smaller on a dense track so that the curve shows
    between them (266 keys used to hide it under 11 px dots)."""
    return 8 if n_keys <= 40 else 6 if n_keys <= 120 else 4


class _KeyPoints(pg.ScatterPlotItem):
    """Key-frame points that can be clicked (select) and dragged (move); data of a point = its frame."""

    def __init__(self) -> None:
        super().__init__(size=key_size(0), pen=pg.mkPen("w", width=1), brush=_KEY_BRUSH, hoverable=True,
                         hoverSize=12)
        self.on_select: Callable[[int, bool], None] | None = None
        self.on_drop: Callable[[int, float, float], None] | None = None
        self.dragging: int | None = None

    def mouseClickEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph override
        points = self.pointsAt(ev.pos()) if ev.button() == QtCore.Qt.MouseButton.LeftButton else []
        if len(points) == 0:
            ev.ignore()
            return
        ev.accept()
        if self.on_select is not None:
            shift = bool(ev.modifiers() & QtCore.Qt.KeyboardModifier.ShiftModifier)
            self.on_select(int(points[0].data()), shift)

    def mouseDragEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph override
        if ev.button() != QtCore.Qt.MouseButton.LeftButton:
            ev.ignore()
            return
        if ev.isStart():
            points = self.pointsAt(ev.buttonDownPos())
            if len(points) == 0:
                ev.ignore()
                return
            self.dragging = int(points[0].data())
        elif self.dragging is None:
            ev.ignore()
            return
        ev.accept()
        x, y = ev.pos().x(), min(max(ev.pos().y(), 0.0), 1.0)
        if ev.isFinish():
            frame, self.dragging = self.dragging, None
            if self.on_drop is not None:
                self.on_drop(frame, x, y)
        else:
            self._preview(x, y)

    def _preview(self, x: float, y: float) -> None:
        """Draw the dragged point at the pointer (widget state only; the model changes on drop)."""
        data = self.data
        i = int(np.flatnonzero(data["data"] == self.dragging)[0])
        xs, ys = data["x"].copy(), data["y"].copy()
        xs[i], ys[i] = x, y
        self.setData(x=xs, y=ys, data=data["data"].copy(), size=key_size(len(xs)),
                     brush=[_SELECTED_BRUSH if k == i else _KEY_BRUSH for k in range(len(xs))])


class QtTimeline(pg.GraphicsLayoutWidget):
    """Heart rate + phases and the curve editor of an annotation session (see the module docstring).

    Parameters
    ----------
    session : AnnotateSession
        The rater's session.
    """

    def __init__(self, session: AnnotateSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setBackground("w")
        self.session = session
        self.selected: int | None = None
        self.extra: set[int] = set()  # keys added to the selection with Shift+click
        self.hidden: set[str] = set()  # blendshapes whose curve the rater switched off
        self.machine_hidden: set[str] = set()  # blendshapes whose machine guide the rater switched off
        self.t_s = session.times.t_s
        self.phase_labels: list[tuple[pg.LinearRegionItem, pg.InfLineLabel, str]] = []
        #: how the view follows the current frame (one of :data:`FOLLOW_MODES`)
        self.follow = "page"
        self.hr_plot = self.addPlot(row=0, col=0)
        self._curve_box = _ClickViewBox()
        self.curve_plot = self.addPlot(row=1, col=0, viewBox=self._curve_box)
        # the curve editor gets three quarters of the height (the heart rate is context); the splitter
        # above the timeline makes both taller
        self.ci.layout.setRowStretchFactor(0, 1)
        self.ci.layout.setRowStretchFactor(1, 3)
        self._build_hr()
        self._build_curves()
        self.cursors = [self._cursor(self.hr_plot, movable=True), self._cursor(self.curve_plot, movable=False)]
        self.cursors[0].sigDragged.connect(lambda line: session.go_to_time(line.value()))
        self.setMinimumHeight(260)
        session.frame_changed.connect(self._on_frame)
        session.keys_changed.connect(lambda *_: self.refresh_curves())
        session.blendshape_changed.connect(self._on_blendshape)
        self.refresh_machine()
        self._on_frame(session.frame)

    # -------------------------------------------------------------------------------- building
    def _build_hr(self) -> None:
        plot = self.hr_plot
        plot.setLabel("left", "HR", units="bpm")  # short: "heart rate (bpm)" was clipped at 1280x800
        plot.getAxis("left").setWidth(LEFT_AXIS_PX)
        plot.showGrid(x=True, y=True, alpha=0.2)
        plot.setMouseEnabled(x=True, y=False)
        hr = self.session.session.heart_rate
        t = np.array([h.t_s for h in hr], dtype=float)
        bpm = np.array([h.hr_bpm if (h.valid and h.hr_bpm) else np.nan for h in hr], dtype=float)
        plot.plot(t, bpm, pen=pg.mkPen("#c0002a", width=1.5), connect="finite")
        if np.isfinite(bpm).any():
            plot.setYRange(np.nanmin(bpm) - 5, np.nanmax(bpm) + 12, padding=0)
        self._add_phases(plot)
        self._add_marks(plot)
        start_s, end_s = min(float(self.t_s[0]), 0.0), float(self.t_s[-1])
        plot.setLimits(xMin=start_s, xMax=end_s + 0.01 * max(end_s - start_s, 1.0))  # no negative time
        plot.setXRange(self.t_s[0], self.t_s[-1], padding=0.01)

    def _add_marks(self, plot: pg.PlotItem) -> None:
        """Sync flashes as dashed lines, repetitions as ticks along the top of the heart-rate plot."""
        events = self.session.session.events
        self.sync_lines = []
        for e in events:
            if e.kind == "sync" and e.label == "flash":
                line = pg.InfiniteLine(e.t_s, angle=90, movable=False, label="sync",
                                       pen=pg.mkPen("#806000", width=1, style=QtCore.Qt.PenStyle.DashLine),
                                       labelOpts={"position": 0.1, "color": "#806000"})
                plot.addItem(line)
                self.sync_lines.append(line)
        reps = np.array([e.t_s for e in events if e.kind == "reps"], dtype=float)
        top = plot.vb.viewRange()[1][1]
        self.rep_marks = pg.ScatterPlotItem(reps, np.full(len(reps), top - 4.0), symbol="t", size=6,
                                            pen=None, brush=pg.mkBrush("#303030"))
        self.rep_marks.setToolTip("repetitions counted while recording (F9)")
        plot.addItem(self.rep_marks)

    def _add_phases(self, plot: pg.PlotItem) -> None:
        """Shade each phase between its start and end events and name it."""
        starts: dict[str, float] = {}
        for i, e in enumerate(ev for ev in self.session.session.events if ev.kind in ("phase_start", "phase_end")):
            if e.kind == "phase_start":
                starts[e.label] = e.t_s
            elif e.label in starts:
                region = pg.LinearRegionItem((starts.pop(e.label), e.t_s), movable=False,
                                             brush=_PHASE_BRUSHES[i // 2 % 2], pen=pg.mkPen(None))
                region.setZValue(-10)
                plot.addItem(region)
                label = pg.InfLineLabel(region.lines[0], "", position=0.93, anchors=[(0, 0), (0, 0)],
                                        color="#404040")
                self.phase_labels.append((region, label, e.label))
        plot.vb.sigXRangeChanged.connect(self._fit_phase_labels)
        plot.vb.sigResized.connect(self._fit_phase_labels)

    def _fit_phase_labels(self, *_: object) -> None:
        """Elide each phase's name to its band's width on screen, so that no name runs into the next."""
        view = self.hr_plot.vb
        for region, label, text in self.phase_labels:
            lo, hi = region.getRegion()
            width_px = view.mapViewToScene(QtCore.QPointF(hi, 0)).x() - view.mapViewToScene(QtCore.QPointF(lo, 0)).x()
            metrics = QtGui.QFontMetricsF(label.textItem.font())
            # the label sits a few pixels into its band (its text item's margins): keep them on both sides
            shown = metrics.elidedText(text, QtCore.Qt.TextElideMode.ElideRight, max(width_px - 12, 0.0))
            label.setFormat(shown.replace("{", "{{").replace("}", "}}"))  # a format string: braces doubled
            label.setToolTip(text)

    def _build_curves(self) -> None:
        plot = self.curve_plot
        plot.setLabel("left", "weight")
        plot.getAxis("left").setWidth(LEFT_AXIS_PX)  # as wide as the HR plot's: the time axes line up
        plot.setLabel("bottom", "session time", units="s")
        plot.showGrid(x=True, y=True, alpha=0.2)
        plot.setMouseEnabled(x=True, y=False)
        plot.setYRange(-0.05, 1.05, padding=0)
        plot.setXLink(self.hr_plot)
        self.hr_plot.getAxis("bottom").setStyle(showValues=False)
        self.no_face = pg.BarGraphItem(x0=[], width=[], y0=-0.05, height=1.1, brush=_NO_FACE_BRUSH, pen=pg.mkPen(None))
        self.no_face.setZValue(-20)
        plot.addItem(self.no_face)
        self.no_face_labels: list[pg.TextItem] = []
        self.machine_curves = {n: plot.plot(pen=pg.mkPen(self.colour(n), width=1.2, style=QtCore.Qt.PenStyle.DashLine))
                               for n in self.session.blendshape_names}
        for item in self.machine_curves.values():
            item.setZValue(-5)  # under the rater's own curves and keys
        self.others = {n: plot.plot(pen=pg.mkPen(self.colour(n), width=1.2)) for n in self.session.blendshape_names}
        self.current_curve = plot.plot(pen=pg.mkPen(self.colour(self.session.blendshape), width=2.5))
        #: the stretches of the current curve whose nearest key is the machine's (accepted, not edited)
        self.machine_keyed_curve = plot.plot(pen=pg.mkPen(MACHINE_KEY_COLOUR, width=2.5))
        self.keys = _KeyPoints()
        plot.addItem(self.keys)
        self.keys.on_select = self.select_key
        self.keys.on_drop = self._on_drop
        self._curve_box.on_click = lambda x, y: self.session.go_to_time(x)
        self._curve_box.on_double_click = self._on_double_click
        self.title = pg.TextItem(color="#1f5fbf", anchor=(0, 0))
        plot.addItem(self.title, ignoreBounds=True)

    def colour(self, name: str) -> str:
        """The colour of a blendshape's curve."""
        return CURVE_COLOURS[self.session.blendshape_names.index(name) % len(CURVE_COLOURS)]

    def set_shown(self, name: str, shown: bool) -> None:
        """Show or hide the (non-current) curve of blendshape ``name``."""
        self.hidden.discard(name) if shown else self.hidden.add(name)
        self.refresh_curves()

    def set_machine_shown(self, name: str, shown: bool) -> None:
        """Show or hide the machine guide of blendshape ``name``."""
        self.machine_hidden.discard(name) if shown else self.machine_hidden.add(name)
        self.refresh_curves()

    def refresh_machine(self) -> None:
        """Read the session's machine guide again: the dashed curves and the no-face shading."""
        guide = self.session.machine
        for item in self.no_face_labels:
            self.curve_plot.removeItem(item)
        self.no_face_labels = []
        spans = guide.no_face_spans() if guide is not None else []
        last = len(self.t_s) - 1
        t0 = np.array([self.t_s[a] for a, _ in spans], dtype=float)
        t1 = np.array([self.t_s[min(b + 1, last)] for _, b in spans], dtype=float)
        self.no_face.setOpts(x0=t0, width=np.maximum(t1 - t0, 1e-3), y0=-0.05, height=1.1)
        self.no_face.setToolTip("no face: the machine rater found no face on these frames")
        for t in t0[:_MAX_NO_FACE_LABELS]:
            label = pg.TextItem("no face", color="#505050", anchor=(0, 1))
            label.setPos(float(t), -0.04)
            self.curve_plot.addItem(label, ignoreBounds=True)
            self.no_face_labels.append(label)
        for name, item in self.machine_curves.items():
            curve = guide.curve(name) if guide is not None else None
            item.setData(self.t_s, curve if curve is not None else np.full(len(self.t_s), np.nan), connect="finite")
        self.refresh_curves()

    def machine_visible(self, name: str) -> bool:
        """True when blendshape ``name``'s machine guide is drawn."""
        return self.machine_curves[name].isVisible()

    def visible_frames(self) -> tuple[int, int]:
        """First and last frame of the time shown."""
        lo, hi = self.curve_plot.viewRange()[0]
        first, last = self.session.times.frame_at(lo), self.session.times.frame_at(hi)
        return min(first, last), max(first, last)

    # ---------------------------------------------------------------------------------- zoom
    def zoom(self, factor: float) -> None:
        """Zoom the time axis by ``factor`` (> 1: in) about the cursor."""
        lo, hi = self.curve_plot.viewRange()[0]
        t = float(self.t_s[self.session.frame])
        span = max((hi - lo) / factor, 0.5)
        self._show_span(t - span / 2, span)

    def frame_all(self) -> None:
        """Show the whole session (F)."""
        self.curve_plot.setXRange(float(self.t_s[0]), float(self.t_s[-1]), padding=0.01)

    def visible_span_s(self) -> float:
        """Seconds of session time shown."""
        lo, hi = self.curve_plot.viewRange()[0]
        return float(hi - lo)

    # ---------------------------------------------------------------------------- selection
    @property
    def selection(self) -> list[int]:
        """Selected key frames, sorted (the clicked key and those added with Shift+click)."""
        return sorted(self.extra | ({self.selected} if self.selected is not None else set()))

    def set_selection(self, frames: list[int]) -> None:
        """Select these keys of the current track (no frame change)."""
        frames = sorted(frames)
        self.selected = frames[0] if frames else None
        self.extra = set(frames[1:])
        self.refresh_curves()

    def select_all(self) -> None:
        """Select every key of the current track."""
        self.set_selection([k.frame for k in self.session.track.keys])

    def _cursor(self, plot: pg.PlotItem, movable: bool) -> pg.InfiniteLine:
        line = pg.InfiniteLine(angle=90, movable=movable, pen=pg.mkPen("#00a040", width=2),
                               hoverPen=pg.mkPen("#00d060", width=3))
        plot.addItem(line, ignoreBounds=True)
        return line

    # ------------------------------------------------------------------------------- updates
    def refresh_curves(self) -> None:
        """Redraw the rater's curves and the current blendshape's keys from the model."""
        frames = np.arange(self.session.n_frames)
        for name, item in self.others.items():
            values = self.session.annotations.tracks[name].evaluate(frames)
            item.setData(self.t_s, values, connect="finite")
            item.setVisible(name != self.session.blendshape and name not in self.hidden)
        guide = self.session.machine
        for name, item in self.machine_curves.items():
            current = name == self.session.blendshape
            item.setVisible(guide is not None and name not in self.machine_hidden
                            and (current or name not in self.hidden))
            colour = pg.mkColor(self.colour(name))
            colour.setAlpha(255 if current else 110)  # the other blendshapes' guides faint
            item.setPen(pg.mkPen(colour, width=2.0 if current else 1.0, style=QtCore.Qt.PenStyle.DashLine))
        self.current_curve.setPen(pg.mkPen(self.colour(self.session.blendshape), width=2.5))
        values = self.session.track.evaluate(frames)
        human = self.session.track.human_mask(frames) | ~np.isfinite(values)
        # a frame on each side of a change belongs to both curves, so that they join
        edge = np.convolve(human.astype(int), [1, 1, 1], mode="same")
        self.current_curve.setData(self.t_s, np.where(edge > 0, values, np.nan), connect="finite")
        self.machine_keyed_curve.setData(self.t_s, np.where(edge < 3, values, np.nan), connect="finite")
        kf, kw, _ = self.session.track.arrays()
        machine = np.array([not k.human for k in self.session.track.keys], dtype=bool)
        keyed = set(kf.tolist())
        if self.selected is not None and self.selected not in keyed:
            self.selected = None
        self.extra &= keyed
        chosen = set(self.selection)
        own = pg.mkBrush(self.colour(self.session.blendshape))
        brushes = [_SELECTED_BRUSH if f in chosen else _MACHINE_BRUSH if m else own for f, m in zip(kf, machine)]
        size = key_size(len(kf))
        self.keys.setData(x=self.t_s[kf], y=kw, data=kf, brush=brushes, symbol=["d" if m else "o" for m in machine],
                          size=[size + 3 if m else size for m in machine])
        picked = f", {len(chosen)} selected" if len(chosen) > 1 else ""
        accepted = f" ({int(machine.sum())} the machine's, grey)" if machine.any() else ""
        self.title.setColor(self.colour(self.session.blendshape))
        self.title.setText(f"{self.session.blendshape} ({self.session.rater}): {len(kf)} keys{accepted}{picked}")
        self.title.setPos(self.t_s[0], 1.05)

    def _on_frame(self, frame: int) -> None:
        if self.selected is not None and self.selected != frame and not self.extra:
            self.select_key(None)  # Del and Ctrl+C act on the current frame once it moves away
        t = float(self.t_s[frame])
        for line in self.cursors:
            if line.value() != t:
                line.blockSignals(True)
                line.setValue(t)
                line.blockSignals(False)
        self.follow_cursor(t)

    def follow_cursor(self, t_s: float) -> None:
        """Bring time ``t_s`` into view as :attr:`follow` says (page: a new page when it leaves the view)."""
        lo, hi = self.curve_plot.viewRange()[0]
        span = hi - lo
        if self.follow == "centre":
            self._show_span(t_s - span / 2, span)
        elif self.follow == "page" and not lo <= t_s <= hi:
            self._show_span(t_s - 0.05 * span if t_s > hi else t_s - 0.95 * span, span)

    def _show_span(self, lo: float, span: float) -> None:
        """Show ``span`` seconds from ``lo``, shifted to stay within the session (never negative time)."""
        first_s, end_s = min(float(self.t_s[0]), 0.0), float(self.t_s[-1])
        last_s = end_s + 0.01 * max(end_s - first_s, 1.0)
        span = min(span, last_s - first_s)
        lo = max(min(lo, last_s - span), first_s)
        self.curve_plot.setXRange(lo, lo + span, padding=0)

    def _on_blendshape(self, _name: str) -> None:
        self.selected = None
        self.extra = set()
        self.refresh_curves()

    def select_key(self, frame: int | None, extend: bool = False) -> None:
        """Select the current track's key on ``frame`` (None: clear) and go to its frame.

        ``extend`` (Shift+click) toggles the key in the selection instead, without moving.
        """
        if extend and frame is not None:
            if frame in self.selection:
                self.set_selection([f for f in self.selection if f != frame])
            else:
                self.set_selection([*self.selection, frame])
            return
        self.selected, self.extra = frame, set()
        if frame is not None:
            self.session.set_frame(frame)
        self.refresh_curves()

    def _on_drop(self, frame: int, x: float, y: float) -> None:
        new_frame = self.session.times.frame_at(x)
        try:
            key = self.session.move_key(frame, new_frame, y)
        except ValueError:  # another key sits there: keep the old position
            self.refresh_curves()
            return
        self.select_key(key.frame)

    def _on_double_click(self, x: float, y: float) -> None:
        frame = self.session.times.frame_at(x)
        self.session.set_frame(frame)
        self.session.set_key(min(max(y, 0.0), 1.0), frame)
        self.select_key(frame)

    def key_point_scene_pos(self, frame: int) -> QtCore.QPointF:
        """Scene position of the key on ``frame`` (for tests and tooltips); KeyError if it has none."""
        key = self.session.track.get(frame)
        if key is None:
            raise KeyError(f"no key on frame {frame}")
        return self._curve_box.mapViewToScene(QtCore.QPointF(self.t_s[frame], key.weight))

    def time_scene_pos(self, t_s: float, weight: float) -> QtCore.QPointF:
        """Scene position of a point of the curve editor."""
        return self._curve_box.mapViewToScene(QtCore.QPointF(t_s, weight))
