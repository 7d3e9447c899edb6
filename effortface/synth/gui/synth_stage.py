"""The Synthesize stage: play a motion clip through a face model, tune the character, export curves.

:class:`QtSynthStage` views a :class:`~effortface.synth.synth_session.SynthSession`: the controls call its
methods, its callbacks redraw the views, and a QTimer moves its play head with the wall time
(the rule: a view writes back only through model methods and keeps widget state only). Views: a stick figure of the skeleton (front or side projection), the parametric
face (:func:`effortface.annotate.face.render_face`) driven by the weights at the play head, and plots of w and
p, NHR and HR, EPOC and the blendshape weights with a moving time cursor.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.annotate.face import render_face
from effortface.core.gui.qt_compat import guard_none_refcount
from effortface.core.errors import UserError
from effortface.core.gui.widgets import QtElidedComboBox, QtElidedLabel, caption
from effortface.core.participant import SEXES
from effortface.synth.motion import CMU_UNIT_M
from effortface.synth.read_options import UP_AXES
from effortface.synth.runtime import AGE_RANGE, HEIGHT_RANGE_M, MASS_RANGE_KG, TRAINING_LEVEL_RANGE
from effortface.synth.synth_session import (
    MAX_LOOPS,
    SynthSession,
    find_clips,
    stick_pairs,
    view_axes,
)

__all__ = ["QtSynthStage", "SynthSession"]

FRAME_MS = 15          # play timer period: about 66 Hz, above the 60 fps target
POLL_MS = 30           # how often finished background recomputes are applied
FACE_SIZE = (320, 240)  # the face preview's smallest size; it grows with the window (4:3)
VIEWS = ("front", "side")
#: the unit choices beside Mapping... (text, metres per file unit; None: from the file)
READ_UNITS: tuple[tuple[str, float | None], ...] = (
    ("unit: file", None), ("m", 1.0), ("cm", 0.01), ("mm", 0.001), ("inch", 0.0254), ("CMU", CMU_UNIT_M))
_WEIGHT_PENS = ("#d62728", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")
#: weights curves are drawn in order, each thinner and dashed differently, half transparent, so a
#: curve lying on another (two blendshapes at 0) still shows along its edges
_WEIGHT_WIDTHS = (4.5, 3.0, 2.0, 1.2)
_WEIGHT_STYLES = (QtCore.Qt.PenStyle.SolidLine, QtCore.Qt.PenStyle.SolidLine,
                  QtCore.Qt.PenStyle.DashLine, QtCore.Qt.PenStyle.DotLine)
_WEIGHT_ALPHA = 170
#: smallest EPOC axis (ml/kg): a clip too short or light for EPOC to build shows a flat line at 0,
#: not noise magnified to fill an axis of 0-0.0008
EPOC_MIN_TOP_ML_PER_KG = 1.0
#: widths of the plots' left and right axes, equal on all four so that their time axes line up
_AXIS_WIDTH_PX = (58, 48)
#: the play head's keys, active application-wide while the stage is shown (key, what it does)
PLAYER_KEYS = (("Space", "play / pause"), ("Left", "one frame back"), ("Right", "one frame on"),
               ("Shift+Left", "1 s back"), ("Shift+Right", "1 s on"), ("Home", "start"), ("End", "end"))
_CURSOR_PEN = pg.mkPen("#202020", width=1, style=QtCore.Qt.PenStyle.DashLine)


def _cache_axes(plot: pg.PlotItem) -> None:
    """Draw axes and grid from a pixmap cache: the moving cursor otherwise repaints them every frame."""
    for name in ("left", "bottom", "right"):
        plot.getAxis(name).setCacheMode(QtWidgets.QGraphicsItem.CacheMode.DeviceCoordinateCache)


def _show_error(label: QtWidgets.QLabel, text: str, is_error: bool) -> None:
    """Status line: errors in red, news in grey."""
    label.setStyleSheet("color:#b00020;" if is_error else "color:#404040;")
    label.setText(text)


def epoc_axis_top(epoc_ml_per_kg: np.ndarray) -> float:
    """Top of the EPOC axis (ml/kg): 5 % above the curve, never below :data:`EPOC_MIN_TOP_ML_PER_KG`."""
    peak = float(np.nanmax(epoc_ml_per_kg)) if len(epoc_ml_per_kg) else 0.0
    return max(1.05 * peak, EPOC_MIN_TOP_ML_PER_KG)


def weight_pen(index: int) -> QtGui.QPen:
    """The pen of the ``index``-th weights curve (colour, width and dash by draw order, see above)."""
    color = QtGui.QColor(_WEIGHT_PENS[index % len(_WEIGHT_PENS)])
    color.setAlpha(_WEIGHT_ALPHA)
    pen = pg.mkPen(color, width=_WEIGHT_WIDTHS[min(index, len(_WEIGHT_WIDTHS) - 1)])
    pen.setStyle(_WEIGHT_STYLES[index % len(_WEIGHT_STYLES)])
    return pen


def _application() -> QtCore.QCoreApplication:
    """The running application (a stage exists only inside one)."""
    app = QtWidgets.QApplication.instance()
    assert app is not None
    return app


def _weights_text(names: tuple[str, ...], weights: np.ndarray, per_line: int = 2) -> str:
    """``name weight`` pairs, ``per_line`` to a line (the face preview's width, whatever the model)."""
    pairs = [f"{n.replace('_', ' ')} {w:.2f}" for n, w in zip(names, weights)]
    return "\n".join("  ".join(pairs[i:i + per_line]) for i in range(0, len(pairs), per_line))


# --------------------------------------------------------------------------- character controls


class QtCharacterPanel(QtWidgets.QGroupBox):
    """Age, sex, height, mass, training level, expressiveness and loads of the character.

    Every control writes through :meth:`SynthSession.set_character` (or ``set_expressiveness``);
    a rejected value is reported through ``on_error`` and the control shows the model's value again.
    """

    def __init__(self, session: SynthSession, on_error: Callable[[str, bool], None],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Character", parent)
        self.session = session
        self._on_error = on_error
        self.form = QtWidgets.QFormLayout(self)
        self.form.setLabelAlignment(QtCore.Qt.AlignmentFlag.AlignRight)
        self.fields: dict[str, Any] = {}  # field -> QDoubleSpinBox or QComboBox
        self.expressiveness: list[QtWidgets.QDoubleSpinBox] = []
        self._build_body()
        self._expr_box = QtWidgets.QGroupBox("Expressiveness (1 = as trained)")
        self._expr_form = QtWidgets.QFormLayout(self._expr_box)
        self.form.addRow(self._expr_box)
        self._build_loads()
        self.rebuild_expressiveness()
        session.model_changed.connect(self.rebuild_expressiveness)
        session.character_changed.connect(self.show_character)

    def _spin(self, lo: float, hi: float, step: float, decimals: int, suffix: str) -> QtWidgets.QDoubleSpinBox:
        box = QtWidgets.QDoubleSpinBox(minimum=lo, maximum=hi, singleStep=step, decimals=decimals)
        box.setSuffix(suffix)
        box.setKeyboardTracking(False)
        return box

    def _add(self, label: str, field: str, widget: Any, row_widget: Any = None) -> None:
        self.fields[field] = widget
        self.form.addRow(label, row_widget or widget)

    def _build_body(self) -> None:
        self._add("Age", "age", self._spin(*AGE_RANGE, 1, 0, " years"))
        sex = QtWidgets.QComboBox()
        sex.addItems(SEXES)
        self._add("Sex", "sex", sex)
        self._add("Height", "height_m", self._spin(*HEIGHT_RANGE_M, 0.01, 2, " m"))
        self._add("Mass", "mass_kg", self._spin(*MASS_RANGE_KG, 1, 1, " kg"))
        tl = self._spin(*TRAINING_LEVEL_RANGE, 0.5, 1, "")
        slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        slider.setRange(0, int(TRAINING_LEVEL_RANGE[1] * 10))
        slider.setTracking(False)  # recompute on release, not on every step of a drag
        slider.valueChanged.connect(lambda v: tl.setValue(v / 10))
        tl.valueChanged.connect(lambda v: slider.setValue(round(v * 10)))
        self.tl_slider = slider
        row = QtWidgets.QHBoxLayout()
        row.addWidget(slider, 1)
        row.addWidget(tl)
        self._add("Training level", "training_level", tl, row)
        self.show_character()
        for field, widget in self.fields.items():
            self._connect(field, widget)

    def _build_loads(self) -> None:
        for label, field in (("Load, left hand", "load_left_kg"), ("Load, right hand", "load_right_kg"),
                             ("Load on the back", "load_back_kg")):
            box = self._spin(0, 100, 1, 1, " kg")
            box.setValue(getattr(self.session.character, field))
            self._add(label, field, box)
            self._connect(field, box)

    def _connect(self, field: str, widget: Any) -> None:
        if isinstance(widget, QtWidgets.QComboBox):
            widget.currentTextChanged.connect(lambda v, f=field: self._write(f, v))
        else:
            widget.valueChanged.connect(lambda v, f=field: self._write(f, float(v)))

    def _write(self, field: str, value: Any) -> None:
        try:
            self.session.set_character(**{field: value})
        except UserError as exc:
            self._on_error(str(exc), True)
            self.show_character()

    def _write_expressiveness(self, index: int, value: float) -> None:
        try:
            self.session.set_expressiveness(index, float(value))
        except UserError as exc:
            self._on_error(str(exc), True)
            self.show_character()

    def rebuild_expressiveness(self) -> None:
        """One spin box per blendshape of the session's model."""
        while self._expr_form.rowCount():
            self._expr_form.removeRow(0)
        self.expressiveness = []
        for i, name in enumerate(self.session.model.blendshapes.names):
            box = self._spin(0, 3, 0.1, 2, "")
            box.setValue(self.session.character.expressiveness[i])
            box.valueChanged.connect(lambda v, i=i: self._write_expressiveness(i, v))
            self._expr_form.addRow(name.replace("_", " "), box)
            self.expressiveness.append(box)

    def show_character(self) -> None:
        """Show the model's character in the controls (without writing back)."""
        c = self.session.character
        for field, widget in self.fields.items():
            widget.blockSignals(True)
            if isinstance(widget, QtWidgets.QComboBox):
                widget.setCurrentText(getattr(c, field))
            else:
                widget.setValue(getattr(c, field))
            widget.blockSignals(False)
        self.tl_slider.blockSignals(True)
        self.tl_slider.setValue(round(c.training_level * 10))
        self.tl_slider.blockSignals(False)
        for box, value in zip(self.expressiveness, c.expressiveness):
            box.blockSignals(True)
            box.setValue(value)
            box.blockSignals(False)


# --------------------------------------------------------------------------- views


class QtSkeletonView(pg.PlotWidget):
    """The skeleton as a stick figure, projected on the body's front or side plane (Z up)."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent, background="w")
        self.setAspectLocked(True)
        self.setMenuEnabled(False)
        self.setMouseEnabled(False, False)
        self.hideButtons()
        self.showGrid(x=True, y=True, alpha=0.2)
        self.setLabel("left", "height (m)")
        _cache_axes(self.getPlotItem())
        self.bones = self.plot([], [], pen=pg.mkPen("#1f4e79", width=3), connect="pairs")
        self.joints = self.plot([], [], pen=None, symbol="o", symbolSize=5, symbolBrush="#1f4e79")
        self.view = "front"
        self._pairs = np.zeros((0, 2), int)
        self._axes = {"front": np.array([1.0, 0.0]), "side": np.array([0.0, 1.0])}
        self._positions: np.ndarray | None = None
        self.hint = pg.TextItem("no clip yet: Open clip... or pick one above", color="#606060",
                                anchor=(0.5, 0.5))
        self.addItem(self.hint)
        self.hint.setPos(0.0, 1.0)
        self.setRange(xRange=(-1, 1), yRange=(0, 2), padding=0)

    def set_skeleton(self, motion: Any) -> None:
        """Bones from the parents, view axes from the body; the range fits every frame of the clip."""
        self.hint.setVisible(False)
        self._pairs = stick_pairs(motion.parents)
        self._axes = view_axes(motion)
        self._positions = motion.positions_m
        self.set_view(self.view)

    def set_view(self, view: str) -> None:
        """``front`` or ``side``."""
        self.view = view
        self.setLabel("bottom", f"{'left-right' if view == 'front' else 'back-front'} (m)")
        if self._positions is not None:
            pts = self._positions[::max(1, len(self._positions) // 200)].reshape(-1, 3)
            h = pts[:, :2] @ self._axes[view]
            self.setRange(xRange=(h.min(), h.max()), yRange=(min(0.0, pts[:, 2].min()), pts[:, 2].max()),
                          padding=0.08)

    def show_pose(self, pose_m: np.ndarray) -> None:
        """Draw one frame's joints (J, 3)."""
        h = pose_m[:, :2] @ self._axes[self.view]
        pairs = self._pairs.ravel()
        self.bones.setData(h[pairs], pose_m[pairs, 2])
        self.joints.setData(h, pose_m[:, 2])


#: the face drawing's gains offered (display only)
FACE_GAINS = {"x1 (true weights)": 1.0, "x2": 2.0, "x4": 4.0}


class QtFacePreview(QtWidgets.QLabel):
    """The parametric face for a weight vector, as large as the label allows (4:3, at least FACE_SIZE)."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumSize(*FACE_SIZE)
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Expanding)
        self.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self._weights = np.zeros(4)
        #: the drawing's gain: small weights (0.1-0.25) look neutral at x1; the weights shown stay true
        self.gain = 1.0
        self.show_weights(self._weights)  # the rest face until a clip plays

    def set_gain(self, gain: float) -> None:
        """Draw the face with the weights times ``gain`` (clipped to 1); the plots and numbers stay true."""
        self.gain = float(gain)
        self.show_weights(self._weights)

    def face_size(self) -> tuple[int, int]:
        """The rendered face's (width, height): the largest 4:3 box in the label, at least FACE_SIZE."""
        w = max(FACE_SIZE[0], min(self.width(), self.height() * 4 // 3))
        return w - w % 4, (w - w % 4) * 3 // 4

    def show_weights(self, weights: np.ndarray) -> None:
        """Render the face (BGR) at :meth:`face_size` and show it."""
        self._weights = np.asarray(weights, float)
        w, h = self.face_size()
        drawn = np.clip(self._weights * self.gain, 0.0, 1.0)
        rgb = np.ascontiguousarray(render_face(drawn, (w, h))[:, :, ::-1])
        image = QtGui.QImage(rgb.data, w, h, 3 * w, QtGui.QImage.Format.Format_RGB888).copy()
        self.setPixmap(QtGui.QPixmap.fromImage(image))

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:
        """Render again at the new size."""
        super().resizeEvent(event)
        if self.pixmap().size().toTuple() != self.face_size():
            self.show_weights(self._weights)


class QtSynthPlots(pg.GraphicsLayoutWidget):
    """w and p, NHR with an HR axis, EPOC and the weights, sharing a time axis and a cursor."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setBackground("w")
        titles = ("work <span style='color:#1f77b4'>w</span> and power "
                  "<span style='color:#888888'>p</span> (W/kg)",
                  "<span style='color:#1f77b4'>NHR</span> (left), as HR in bpm (right)",
                  "EPOC (ml/kg)", "blendshape weights")
        self.plots = {key: self.addPlot(row=i // 2, col=i % 2)
                      for i, key in enumerate(("work", "nhr", "epoc", "weights"))}
        self.cursors = {}
        for (key, plot), title in zip(self.plots.items(), titles):
            plot.setTitle(title)
            plot.setClipToView(True)
            plot.setDownsampling(auto=True, mode="peak")
            plot.showGrid(x=True, y=True, alpha=0.2)
            if key in ("epoc", "weights"):        # the bottom row names the shared time axis
                plot.setLabel("bottom", "time (s)")
            self.cursors[key] = plot.addLine(x=0, pen=_CURSOR_PEN, movable=False)
            plot.setRange(xRange=(0, 10), yRange=(0, 1), padding=0.02)
            plot.showAxis("right")
            plot.getAxis("left").setWidth(_AXIS_WIDTH_PX[0])
            plot.getAxis("right").setWidth(_AXIS_WIDTH_PX[1])
            if key != "nhr":
                plot.getAxis("right").setStyle(showValues=False)
            _cache_axes(plot)
        for key in ("work", "nhr", "epoc"):
            self.plots[key].setXLink(self.plots["weights"])  # one time axis: zoom or pan one, all follow
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.hidden: set[str] = set()  # curves the user hid (kept hidden across recomputes)
        self._hr_view = self._add_hr_axis(self.plots["nhr"])
        self._hr_view.setYRange(60, 190, padding=0)

    def resizeEvent(self, event: QtGui.QResizeEvent | None) -> None:
        """Two columns of equal width whatever the titles' lengths: the four time axes line up."""
        super().resizeEvent(event)
        if not hasattr(self, "ci"):      # pyqtgraph resizes once while it builds
            return
        left, _, right, _ = self.ci.layout.getContentsMargins()
        half = max((self.width() - left - right - self.ci.layout.horizontalSpacing()) / 2 - 2, 50)
        for col in (0, 1):
            self.ci.layout.setColumnFixedWidth(col, half)

    def _add_hr_axis(self, plot: pg.PlotItem) -> pg.ViewBox:
        """A right-hand HR axis on its own view box, kept aligned with the NHR plot."""
        view = pg.ViewBox()
        plot.scene().addItem(view)
        plot.getAxis("right").linkToView(view)
        plot.getAxis("right").setLabel("HR (bpm)")
        view.setXLink(plot)
        plot.vb.sigResized.connect(lambda: view.setGeometry(plot.vb.sceneBoundingRect()))
        return view

    def _curve(self, key: str, name: str, pen: Any, label: str | None = None) -> pg.PlotDataItem:
        if name not in self.curves:
            item = pg.PlotDataItem(pen=pen, name=label)
            # drawn from a pixmap cache: the curves change only on a recompute, the cursor every frame
            item.curve.setCacheMode(QtWidgets.QGraphicsItem.CacheMode.DeviceCoordinateCache)
            self.plots[key].addItem(item)
            self.curves[name] = item
        return self.curves[name]

    def set_curve_visible(self, name: str, visible: bool) -> None:
        """Show or hide one curve (``w_per_kg``, ``p_per_kg``, ``nhr``, ``epoc`` or a blendshape)."""
        if visible:
            self.hidden.discard(name)
        else:
            self.hidden.add(name)
        if name in self.curves:
            self.curves[name].setVisible(visible)

    def show_curves(self, curves: dict[str, np.ndarray], names: tuple[str, ...],
                    hr_range_bpm: tuple[float, float] = (60.0, 190.0)) -> None:
        """Set every curve's data (called when the curves are recomputed).

        ``hr_range_bpm`` (HR at NHR 0 and 1) scales the right-hand HR axis: HR is linear in NHR,
        so one curve read on either axis gives both.
        """
        t = curves["t_s"]
        self._curve("work", "w_per_kg", pg.mkPen("#1f77b4", width=1.5), label="w").setData(t, curves["w_per_kg"])
        self._curve("work", "p_per_kg", pg.mkPen("#aaaaaa"), label="p").setData(t, curves["p_per_kg"])
        self.plots["work"].enableAutoRange(axis="y")
        self._curve("nhr", "nhr", pg.mkPen("#1f77b4", width=2)).setData(t, curves["nhr"])
        self.plots["nhr"].setYRange(-0.02, 1.02, padding=0)
        rest, top = hr_range_bpm
        self._hr_view.setYRange(rest - 0.02 * (top - rest), top + 0.02 * (top - rest), padding=0)
        self._curve("epoc", "epoc", pg.mkPen("#2ca02c", width=2)).setData(t, curves["epoc"])
        self.plots["epoc"].setYRange(0, epoc_axis_top(curves["epoc"]), padding=0)
        for i, name in enumerate(names):
            curve = self._curve("weights", name, weight_pen(i), label=name.replace("_", " "))
            curve.setPen(weight_pen(i))
            curve.setZValue(i)                       # drawn in order: the thinner ones on top
            curve.setData(t, curves[name])
        self.plots["weights"].setYRange(0, 1, padding=0.02)
        spans = [f"<span style='color:{_WEIGHT_PENS[i % len(_WEIGHT_PENS)]}'>{n.replace('_', ' ')}</span>"
                 for i, n in enumerate(names)]
        # two names a line: a one-line title would widen its column and misalign the time axes
        self.plots["weights"].setTitle("weights: " + "<br>".join(
            "  ".join(spans[i:i + 2]) for i in range(0, len(spans), 2)), size="8pt")
        self.plots["weights"].setXRange(0, float(t[-1]) if len(t) else 1, padding=0.01)  # linked
        for name, item in self.curves.items():
            item.setVisible(name not in self.hidden)

    def move_cursor(self, t_s: float) -> None:
        """Move the time cursor of every plot."""
        for line in self.cursors.values():
            line.setValue(t_s)


# --------------------------------------------------------------------------- the stage


class QtSynthStage(QtWidgets.QWidget):
    """The Synthesize stage: clip, model, player, character, plots and export.

    Parameters
    ----------
    session : SynthSession
        The model this stage views and drives.
    motion_dir : Path, optional
        Where the clip dialog opens.
    parent : QWidget, optional
        Parent widget.
    """

    #: stages whose application-wide player keys are enabled (at most one: the last shown)
    _key_owners: "weakref.WeakSet[QtSynthStage]" = weakref.WeakSet()

    def __init__(self, session: SynthSession, motion_dir: Path | None = None,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        guard_none_refcount()  # PySide6 6.12 on CPython 3.11 leaks references to None (see there)
        self.session = session
        self.motion_dir = motion_dir or Path.cwd()
        self.frames_drawn = 0
        self.timings_s = {"model": 0.0, "draw": 0.0}
        self._last_tick = time.perf_counter()
        self._build()
        self._connect_session()
        self.timer = QtCore.QTimer(self, interval=FRAME_MS)
        self.timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self._tick)
        self.poll_timer = QtCore.QTimer(self, interval=POLL_MS)
        self.poll_timer.timeout.connect(session.poll)   # background recomputes land here
        self.poll_timer.start()
        self._on_model_changed()
        if session.motion is not None:
            self._on_motion_changed()
            self._on_curves_changed()

    # ---- layout
    def _build(self) -> None:
        self.status = caption("Open a motion clip (.bvh, .npz, .c3d or joint-positions .csv) to start.")
        self.skeleton = QtSkeletonView()
        self.face = QtFacePreview()
        self.character = QtCharacterPanel(self.session, self.show_status)
        self.plots = QtSynthPlots()
        self.weights_label = QtWidgets.QLabel(alignment=QtCore.Qt.AlignmentFlag.AlignCenter)
        face_widget = QtWidgets.QWidget()
        face_box = QtWidgets.QVBoxLayout(face_widget)
        face_box.setContentsMargins(0, 0, 0, 0)
        self.face_gain = QtWidgets.QComboBox()
        self.face_gain.addItems(list(FACE_GAINS))
        self.face_gain.setToolTip("Draw the face with the weights multiplied (clipped to 1), so that weights "
                                  "of 0.1-0.25 show; the plots, numbers and exports keep the true weights")
        self.face_gain.currentTextChanged.connect(lambda text: self.face.set_gain(FACE_GAINS[text]))
        gain_row = QtWidgets.QHBoxLayout()
        gain_row.addStretch(1)
        gain_row.addWidget(QtWidgets.QLabel("Face drawn at"))
        gain_row.addWidget(self.face_gain)
        gain_row.addStretch(1)
        face_box.addWidget(self.face, 1)
        face_box.addLayout(gain_row)
        face_box.addWidget(self.weights_label)
        views = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        views.addWidget(self.skeleton)
        views.addWidget(face_widget)
        views.setSizes([500, 400])
        self.view_split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)  # the views above the plots
        self.view_split.addWidget(views)
        plots_widget = QtWidgets.QWidget()
        plots_box = QtWidgets.QVBoxLayout(plots_widget)
        plots_box.setContentsMargins(0, 0, 0, 0)
        plots_box.addWidget(self.plots, 1)
        self.curve_row = QtWidgets.QHBoxLayout()
        self.curve_boxes: dict[str, QtWidgets.QCheckBox] = {}
        plots_box.addLayout(self.curve_row)
        self.file_info = self._file_info_view()
        self.bottom_tabs = QtWidgets.QTabWidget()   # the curves, or what the clip's file holds
        self.bottom_tabs.addTab(plots_widget, "Curves")
        self.bottom_tabs.addTab(self.file_info, "File info")
        self.bottom_tabs.setTabToolTip(1, "What the clip's file holds and how it is read (as 'effortface "
                                          "motion inspect FILE'): unit, up axis, labels, segment mapping, gaps")
        self.bottom_tabs.currentChanged.connect(lambda _: self._refresh_file_info())
        self.view_split.addWidget(self.bottom_tabs)
        self.view_split.setSizes([380, 420])
        self.character_scroll = QtWidgets.QScrollArea(widgetResizable=True)
        self.character_scroll.setWidget(self.character)
        self.character_scroll.setMinimumWidth(330)   # the character spans the stage's height
        body = QtWidgets.QHBoxLayout()
        body.addWidget(self.view_split, 1)
        body.addWidget(self.character_scroll, 0)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(self._file_bar())
        layout.addLayout(self._player_bar())
        layout.addLayout(body, 1)
        layout.addWidget(self.status)
        self._build_shortcuts()

    def _file_info_view(self) -> QtWidgets.QPlainTextEdit:
        """The File info panel: the aligned text report of :mod:`effortface.synth.inspect`, fixed-width."""
        view = QtWidgets.QPlainTextEdit(readOnly=True)
        view.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        view.setLineWrapMode(QtWidgets.QPlainTextEdit.LineWrapMode.NoWrap)
        view.setPlainText("no clip yet: open one to see what its file holds")
        self._file_info_for: tuple[Any, ...] | None = None   # (clip, mapping) the text describes
        return view

    def show_file_info(self) -> str:
        """Bring the File info panel up (inspecting the clip if needed); its text."""
        self.bottom_tabs.setCurrentWidget(self.file_info)
        self._refresh_file_info()
        return self.file_info.toPlainText()

    def _refresh_file_info(self) -> None:
        """Inspect the loaded clip when the panel is shown and the clip or mapping changed (the file is
        read again: only on demand)."""
        if self.bottom_tabs.currentWidget() is not self.file_info:
            return
        s = self.session
        key = (s.motion_path, s.mapping_path, id(s.motion))
        if key == self._file_info_for:
            return
        self._file_info_for = key
        if s.motion is None:
            return
        if s.motion_path is None:
            self.file_info.setPlainText("a motion given in memory: no file to inspect")
            return
        from effortface.synth.inspect import inspect_motion
        from effortface.synth.read_options import MotionReadOptions

        options = MotionReadOptions(mapping=None if s.mapping_path is None else str(s.mapping_path))
        try:
            text = "\n".join(inspect_motion(s.motion_path, options).lines())
        except (UserError, OSError) as exc:
            text = f"not inspected: {exc}"
        self.file_info.setPlainText(text)

    def _build_shortcuts(self) -> None:
        """The player's keys (:data:`PLAYER_KEYS`), application-wide: they work whatever has focus.

        Enabled only while the stage is shown (:meth:`showEvent`, :meth:`hideEvent`), so Space
        types a space in another stage's fields.
        """
        actions = (self.toggle_play, lambda: self.step_frames(-1), lambda: self.step_frames(1),
                   lambda: self.step_seconds(-1.0), lambda: self.step_seconds(1.0),
                   lambda: self._guard(lambda: self.session.seek(0.0)),
                   lambda: self._guard(lambda: self.session.seek(self.session.duration_s)))
        self.shortcuts: list[QtGui.QShortcut] = []
        for (key, what), action in zip(PLAYER_KEYS, actions):
            shortcut = QtGui.QShortcut(QtGui.QKeySequence(key), self)
            shortcut.setContext(QtCore.Qt.ShortcutContext.ApplicationShortcut)
            shortcut.setWhatsThis(what)
            shortcut.setEnabled(False)
            shortcut.activated.connect(action)
            self.shortcuts.append(shortcut)
        self._player_keys = {QtGui.QKeySequence(key).toString() for key, _ in PLAYER_KEYS}
        self.play_button.setToolTip("Play / pause (Space, from anywhere in the window)")
        self.loops.setToolTip("Repeat the clip end to end (heart rate and fatigue build up over "
                              "minutes); a new clip starts at 1")
        self.slider.setToolTip("Play head: Left/Right one frame, Shift+Left/Right 1 s, Home/End")

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:
        """Keep the player's keys from the spin boxes' text fields while the stage is shown.

        A focused line edit claims Space, arrows and Home/End before any shortcut (a
        ShortcutOverride); the stage has no free-text field, so its window's widgets give them up.
        """
        if (event.type() == QtCore.QEvent.Type.ShortcutOverride and self.isVisible()
                and isinstance(watched, QtWidgets.QWidget) and watched.window() is self.window()
                and isinstance(event, QtGui.QKeyEvent)
                and QtGui.QKeySequence(event.keyCombination()).toString() in self._player_keys):
            return True      # not accepted: the application-wide shortcut gets the key
        return super().eventFilter(watched, event)

    def toggle_play(self) -> None:
        """Play or pause (Space)."""
        self._guard(lambda: self.session.play(not self.session.playing))

    def step_frames(self, frames: int) -> None:
        """Pause and move the play head by ``frames`` frames (Left/Right)."""
        m = self.session.motion
        if m is not None:
            self.session.play(False)
            self.session.seek((self.session.frame + frames) / m.fps)

    def step_seconds(self, seconds: float) -> None:
        """Move the play head by ``seconds`` (Shift+Left/Right); playback goes on."""
        if self.session.motion is not None:
            self.session.seek(self.session.position_s + seconds)

    def _file_bar(self) -> QtWidgets.QHBoxLayout:
        self.open_clip_button = QtWidgets.QPushButton("Open clip...")
        self.open_clip_button.clicked.connect(self._ask_clip)
        self.clip_label = QtElidedLabel("no clip")
        self.clip_combo = self._clip_combo()
        self.clip_combo.activated.connect(self._on_clip_picked)
        self.mapping_button = QtWidgets.QPushButton("Mapping...")
        self.mapping_button.setToolTip("a joint-to-segment mapping (JSON) for a skeleton the built-in "
                                       "conventions and marker sets do not know")
        self.mapping_button.clicked.connect(self._ask_mapping)
        self._reading_controls()
        self.open_model_button = QtWidgets.QPushButton("Open model...")
        self.open_model_button.clicked.connect(self._ask_model)
        self.default_model_button = QtWidgets.QPushButton("Built-in rule model")
        self.default_model_button.clicked.connect(lambda: self.load_model("default"))
        self.last_model_button = QtWidgets.QPushButton("Last trained model")
        self.last_model_button.clicked.connect(lambda: self.load_model(self.last_model_button.toolTip()))
        self.last_model_button.hide()
        self.model_label = QtElidedLabel()
        self.export_csv_button = QtWidgets.QPushButton("Export CSV...")
        self.export_csv_button.clicked.connect(lambda: self._ask_export("csv"))
        self.export_livelink_button = QtWidgets.QPushButton("Export Live Link Face...")
        self.export_livelink_button.clicked.connect(lambda: self._ask_export("livelink"))
        bar = QtWidgets.QHBoxLayout()
        for w, stretch in ((self.open_clip_button, 0), (self.clip_combo, 0), (self.clip_label, 1),
                           (self.mapping_button, 0), (self.unit_combo, 0), (self.up_combo, 0),
                           (self.trust_check, 0), (QtWidgets.QLabel("Model:"), 0), (self.model_label, 1),
                           (self.last_model_button, 0), (self.open_model_button, 0),
                           (self.default_model_button, 0)):
            bar.addWidget(w, stretch)     # the two names share the room left (elided if short of it)
        return bar

    def _reading_controls(self) -> None:
        """Unit, up axis and trust beside Mapping... (``--unit-m``, ``--up``, ``--trust-skeleton``)."""
        self.unit_combo = QtWidgets.QComboBox()
        self.unit_combo.setToolTip("the clip's length unit (--unit-m; CMU: cgspeed BVH, 0.05644 m); 'unit: "
                                   "file' decides from the file or the skeleton's size")
        for text, unit_m in READ_UNITS:
            self.unit_combo.addItem(text, unit_m)
        self.up_combo = QtWidgets.QComboBox()
        self.up_combo.setToolTip("the clip's up axis (--up); 'up: file' decides from the file or gravity "
                                 "over the clip")
        self.up_combo.addItem("up: file", None)
        for axis in UP_AXES:
            self.up_combo.addItem(f"up {axis}", axis)
        self.trust_check = QtWidgets.QCheckBox("Trust")
        self.trust_check.setToolTip("trust the skeleton: read a body outside the human ranges (a child, a "
                                    "creature) on purpose (--trust-skeleton)")
        for combo in (self.unit_combo, self.up_combo):
            combo.activated.connect(lambda _index: self._on_reading())
        self.trust_check.toggled.connect(lambda _on: self._on_reading())

    def set_reading(self, unit_m: float | None = None, up: str | None = None, trust_skeleton: bool = False) -> bool:
        """Read clips with this unit and up axis, trusted or not (errors shown in the stage; the
        controls show the options in force)."""
        done = self._guard(lambda: self.session.set_reading(unit_m=unit_m, up=up, trust_skeleton=trust_skeleton))
        read = self.session.read
        for combo, value in ((self.unit_combo, read.unit_m), (self.up_combo, read.up)):
            at = combo.findData(value)
            if at < 0:  # a unit the list does not name
                combo.addItem(f"{value:g} m", value)
                at = combo.count() - 1
            combo.setCurrentIndex(at)
        with QtCore.QSignalBlocker(self.trust_check):
            self.trust_check.setChecked(read.trust_skeleton)
        return done

    def _on_reading(self) -> None:
        self.set_reading(self.unit_combo.currentData(), self.up_combo.currentData(), self.trust_check.isChecked())

    def _clip_combo(self) -> QtWidgets.QComboBox:
        """The clips of the motion folder after a neutral entry; its width does not follow the names.

        The list that drops down is as wide as the names need (up to 640 pixels); the box elides the
        chosen clip's path in the middle (its file name stays in view).
        """
        combo = QtElidedComboBox()
        combo.setToolTip(f"motion clips found in {self.motion_dir}")
        combo.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        combo.setMinimumContentsLength(18)
        combo.setMaximumWidth(230)
        combo.addItem(f"clips in {self.motion_dir.name or self.motion_dir}...", None)
        for path in find_clips(self.motion_dir):
            combo.addItem(str(path.relative_to(self.motion_dir)), str(path))
        combo.setEnabled(combo.count() > 1)
        combo.view().setMinimumWidth(min(combo.view().sizeHintForColumn(0) + 24, 640))
        return combo

    def _player_bar(self) -> QtWidgets.QHBoxLayout:
        self.play_button = QtWidgets.QPushButton("Play")
        self.play_button.setCheckable(True)
        self.play_button.toggled.connect(self._on_play_toggled)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.slider.valueChanged.connect(self._on_slider)
        self.time_label = QtWidgets.QLabel("0.00 / 0.00 s")
        self.loops = QtWidgets.QSpinBox(minimum=1, maximum=MAX_LOOPS, value=self.session.loops)
        self.loops.setSuffix(" x")
        self.loops.setKeyboardTracking(False)
        self.loops.valueChanged.connect(self._on_loops)
        self.view_combo = QtWidgets.QComboBox()
        self.view_combo.addItems(["front view", "side view"])
        self.view_combo.currentIndexChanged.connect(self._on_view)
        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(self.play_button)
        bar.addWidget(self.slider, 1)
        bar.addWidget(self.time_label)
        bar.addWidget(QtWidgets.QLabel("Repeat clip"))
        bar.addWidget(self.loops)
        bar.addWidget(self.view_combo)
        bar.addWidget(self.export_csv_button)
        bar.addWidget(self.export_livelink_button)
        return bar

    def _connect_session(self) -> None:
        s = self.session
        s.model_changed.connect(self._on_model_changed)
        s.motion_changed.connect(self._on_motion_changed)
        s.curves_changed.connect(self._on_curves_changed)
        s.position_changed.connect(self._on_position)
        s.playing_changed.connect(self._on_playing_changed)
        s.status_changed.connect(self.show_status)

    # ---- actions (each writes through the session)
    def show_status(self, text: str, is_error: bool = False) -> None:
        """Show a message in the status line (errors in red)."""
        _show_error(self.status, text, is_error)

    def _guard(self, fn: Callable[[], Any]) -> bool:
        """Run ``fn``; expected errors go to the status line, the previous state stays."""
        try:
            fn()
        except (UserError, OSError) as exc:
            self.show_status(str(exc), True)
            return False
        return True

    def load_clip(self, path: str | Path) -> bool:
        """Load a clip (errors shown in the stage)."""
        return self._guard(lambda: self.session.load_motion(path))

    def offer_model(self, path: str | Path) -> None:
        """Offer the model Train exported last: a button that loads it (its folder in the tooltip)."""
        self.last_model_button.setText(f"Last trained: {Path(path).name}")
        self.last_model_button.setToolTip(str(path))
        self.last_model_button.show()

    def load_model(self, path: str | Path) -> bool:
        """Load a bundle folder or ``"default"`` (errors shown in the stage)."""
        return self._guard(lambda: self.session.load_model(path))

    def export(self, path: str | Path, fmt: str = "csv") -> bool:
        """Export the curves; an existing file is replaced only if the user agrees."""
        path = Path(path)
        overwrite = path.exists() and self.confirm_overwrite(path)
        if path.exists() and not overwrite:
            self.show_status(f"not exported: {path} exists and was kept", False)
            return False
        return self._guard(lambda: self.session.export(path, fmt, overwrite=overwrite))

    def confirm_overwrite(self, path: Path) -> bool:
        """Ask whether to replace ``path`` (tests replace this method)."""
        answer = QtWidgets.QMessageBox.question(self, "Replace file?", f"{path} exists. Replace it?")
        return answer == QtWidgets.QMessageBox.StandardButton.Yes

    def _ask_clip(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open motion clip", str(self.motion_dir),
                                                        "Motion (*.bvh *.npz *.c3d *.csv)")
        if path:
            self.load_clip(path)

    def _on_clip_picked(self, index: int) -> None:
        path = self.clip_combo.itemData(index)
        if path:
            self.load_clip(path)

    def set_mapping(self, path: str | Path | None) -> bool:
        """Use a mapping file for the clips, None for the built-in conventions (errors shown in the stage)."""
        done = self._guard(lambda: self.session.set_mapping(path))
        self._refresh_file_info()
        return done

    def _ask_mapping(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Joint-to-segment mapping", str(self.motion_dir),
                                                        "Mapping (*.json)")
        if path:
            self.set_mapping(path)

    def _ask_model(self) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Open model bundle folder")
        if path:
            self.load_model(path)

    def _ask_export(self, fmt: str) -> None:
        suggested = str(self.session.default_export_path(fmt))
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Export curves", suggested, "CSV (*.csv)")
        if path:
            self.export(path, fmt)

    def _on_play_toggled(self, checked: bool) -> None:
        if not self._guard(lambda: self.session.play(checked)):
            self.play_button.setChecked(False)

    def _on_slider(self, frame: int) -> None:
        if self.session.motion is not None and not self.session.playing:
            self.session.seek(frame / self.session.motion.fps)

    def _on_loops(self, loops: int) -> None:
        self._guard(lambda: self.session.set_loops(loops))

    def _on_view(self, index: int) -> None:
        m = self.session.motion
        self.skeleton.set_view(VIEWS[index])
        if m is not None:
            self.skeleton.show_pose(self.session.pose_at())

    # ---- session callbacks (views only)
    def _on_model_changed(self) -> None:
        self.model_label.setText(Path(self.session.model.name).name or self.session.model.name)
        self.model_label.setToolTip(self.session.model.name)
        for name, curve in list(self.plots.curves.items()):
            if name not in self.session.model.columns:
                curve.getViewBox().removeItem(curve)
                del self.plots.curves[name]

    def _on_motion_changed(self) -> None:
        m = self.session.motion
        assert m is not None
        self.clip_label.setText(f"{self.session.motion_path.name if self.session.motion_path else 'clip'}"
                                f"  ({m.n_frames} frames, {m.fps:g} Hz)")
        self.clip_label.setToolTip(f"{self.session.motion_path or 'a motion given in memory'}: "
                                   f"{m.n_frames} frames at {m.fps:g} Hz")
        self._show_clip_in_combo(self.session.motion_path)
        self._refresh_file_info()
        self.skeleton.set_skeleton(m)
        self.loops.blockSignals(True)
        self.loops.setValue(self.session.loops)     # a new clip starts at 1 repeat
        self.loops.blockSignals(False)

    def _show_clip_in_combo(self, path: Path | None) -> None:
        """The combo shows the loaded clip, or its neutral first entry if the clip is not listed."""
        index = 0
        if path is not None:
            wanted = Path(path).resolve()
            index = next((i for i in range(1, self.clip_combo.count())
                          if Path(self.clip_combo.itemData(i)).resolve() == wanted), 0)
        self.clip_combo.setCurrentIndex(index)       # emits no activated: loads nothing

    def _on_curves_changed(self) -> None:
        s = self.session
        params = s.model.physiology_params(s.character)
        self.plots.show_curves(s.curves, s.model.blendshapes.names,
                               (float(params.hr_rest_bpm), float(params.hr_max_bpm)))
        self._sync_curve_boxes()
        self.slider.blockSignals(True)
        self.slider.setRange(0, max(s.n_frames - 1, 0))
        self.slider.blockSignals(False)
        self.loops.blockSignals(True)
        self.loops.setValue(s.loops)
        self.loops.blockSignals(False)

    def _sync_curve_boxes(self) -> None:
        """One check box per curve under the plots (Show: w, p, NHR, EPOC, each blendshape): untick to
        hide a curve that covers another."""
        names = list(self.plots.curves)
        if names == list(self.curve_boxes):
            return
        while self.curve_row.count():
            item = self.curve_row.takeAt(0)
            widget = item.widget() if item is not None else None
            if widget is not None:
                widget.deleteLater()
        self.curve_boxes = {}
        self.curve_row.addWidget(QtWidgets.QLabel("Show:"))
        for name in names:
            box = QtWidgets.QCheckBox(name.replace("_per_kg", "").replace("_", " "))
            box.setChecked(name not in self.plots.hidden)
            box.setToolTip(f"Show or hide the {name} curve")
            box.toggled.connect(lambda on, n=name: self.plots.set_curve_visible(n, on))
            self.curve_row.addWidget(box)
            self.curve_boxes[name] = box
        self.curve_row.addStretch(1)

    def _on_playing_changed(self, playing: bool) -> None:
        self.play_button.blockSignals(True)
        self.play_button.setChecked(playing)
        self.play_button.setText("Pause" if playing else "Play")
        self.play_button.blockSignals(False)
        self._last_tick = time.perf_counter()
        self.timer.start() if playing else self.timer.stop()

    def _tick(self) -> None:
        now = time.perf_counter()
        self.session.advance(now - self._last_tick)
        self._last_tick = now

    def _on_position(self, frame: int) -> None:
        s = self.session
        if not s.n_frames:
            return
        t0 = time.perf_counter()
        weights, pose, t_s = s.weights_at(frame), s.pose_at(frame), float(s.curves["t_s"][frame])
        t1 = time.perf_counter()
        self.skeleton.show_pose(pose)
        self.face.show_weights(weights)
        self.weights_label.setText(_weights_text(s.model.blendshapes.names, weights))
        self.plots.move_cursor(t_s)
        self.slider.blockSignals(True)
        self.slider.setValue(frame)
        self.slider.blockSignals(False)
        self.time_label.setText(f"{t_s:6.2f} / {s.duration_s:.2f} s   HR {s.curves['hr_bpm'][frame]:.0f} bpm")
        self.timings_s["model"] += t1 - t0
        self.timings_s["draw"] += time.perf_counter() - t1
        self.frames_drawn += 1

    # ---- hosting
    def showEvent(self, event: QtGui.QShowEvent) -> None:
        """Enable the player's application-wide keys (taken from any other Synthesize stage still
        alive: two enabled application shortcuts on one key are ambiguous and neither fires)."""
        for other in list(QtSynthStage._key_owners):
            if other is not self:
                for shortcut in other.shortcuts:
                    shortcut.setEnabled(False)
        QtSynthStage._key_owners.add(self)
        for shortcut in self.shortcuts:
            shortcut.setEnabled(True)
        _application().installEventFilter(self)
        super().showEvent(event)

    def hideEvent(self, event: QtGui.QHideEvent) -> None:
        """Pause playback and release the player's keys when the stage is hidden."""
        QtSynthStage._key_owners.discard(self)
        for shortcut in self.shortcuts:
            shortcut.setEnabled(False)
        _application().removeEventFilter(self)
        if self.session.playing:
            self.session.play(False)
        super().hideEvent(event)

    def shutdown(self) -> None:
        """Stop playback and the background recomputes (the main window calls this on exit)."""
        QtSynthStage._key_owners.discard(self)
        for shortcut in self.shortcuts:
            shortcut.setEnabled(False)
        self.timer.stop()
        self.poll_timer.stop()
        _application().removeEventFilter(self)
        self.session.playing = False
        self.session.shutdown()

    def settled(self) -> bool:
        """True when no recompute runs in the background."""
        return not self.session.busy
