"""The live view: camera preview, HR plot with zones, large HR/RR figures and the recording counters.

The view holds only what it draws. The capture stage drains the recorder's queues on a QTimer and
calls :meth:`QtLiveView.add_samples`, :meth:`set_frame` and :meth:`set_status` (the rule: worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

#: heights (fraction of the plot) of successive marker labels: six rows so close lines do not crowd
_LABEL_POSITIONS = (0.96, 0.88, 0.80, 0.72, 0.64, 0.56)
#: approximate width of one label character, pixels (a label's extent on the time axis)
_CHAR_PX = 7.5
#: height of a label row, pixels
_ROW_PX = 17.0
#: seconds of HR shown on the plot
WINDOW_S = 300.0
#: seconds of the strap watched after Stop drawn in the live strap area
MONITOR_S = 60.0
#: (name, low, high) as fractions of the heart-rate reserve (Karvonen), with their colours
ZONES = (("Z1", 0.5, 0.6, "#9ecae1"), ("Z2", 0.6, 0.7, "#a1d99b"), ("Z3", 0.7, 0.8, "#fdd49e"),
         ("Z4", 0.8, 0.9, "#fc9272"), ("Z5", 0.9, 1.0, "#de2d26"))


def hr_zones(hr_rest_bpm: float, hr_max_bpm: float) -> list[tuple[str, float, float]]:
    """Heart-rate zones in bpm from the heart-rate reserve (Karvonen).

    Parameters
    ----------
    hr_rest_bpm, hr_max_bpm : float
        Resting and maximal heart rate.

    Returns
    -------
    list of (name, low_bpm, high_bpm)
    """
    reserve = hr_max_bpm - hr_rest_bpm
    return [(name, hr_rest_bpm + lo * reserve, hr_rest_bpm + hi * reserve) for name, lo, hi, _ in ZONES]


def format_bytes(n_bytes: int) -> str:
    """Human-readable size: ``512 B``, ``3.4 MB``."""
    size = float(n_bytes)
    for unit in ("B", "kB", "MB", "GB"):
        if size < 1000 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1000
    return f"{size:.1f} GB"  # pragma: no cover


class QtLiveView(QtWidgets.QWidget):
    """Camera preview, HR plot, large HR/RR and recording counters.

    Parameters
    ----------
    parent : QWidget, optional
        Parent widget.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self._t_s = np.empty(0)
        self._hr_bpm = np.empty(0)
        self._zone_items: list[pg.LinearRegionItem] = []
        self._markers: list[pg.InfiniteLine] = []
        self.follow = True
        self._build()

    def _build(self) -> None:
        self.preview = QtWidgets.QLabel("no camera")
        self.preview.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.preview.setMinimumSize(240, 130)  # with the live strap's plot under it at 1280x800
        self.preview.setSizePolicy(QtWidgets.QSizePolicy.Policy.Ignored,
                                   QtWidgets.QSizePolicy.Policy.Ignored)
        self.preview.setStyleSheet("background: #202020; color: #c0c0c0;")
        self.hr_label = _BigLabel("--", "heart rate (bpm)", 38)
        self.rr_label = _BigLabel("--", "last R-R interval (ms)", 22)
        self.counters = _Counters()
        self.plot = self._make_plot()
        self.follow_box = QtWidgets.QCheckBox("follow live (wheel/drag the plot to zoom)")
        self.follow_box.setChecked(True)
        self.follow_box.toggled.connect(self.set_follow)
        self.preview_caption = QtWidgets.QLabel("")
        self.preview_caption.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        camera = QtWidgets.QVBoxLayout()
        camera.setSpacing(2)
        camera.addWidget(self.preview, 1)
        camera.addWidget(self.preview_caption)
        camera.addWidget(self._make_monitor())  # after Stop, under the camera (whose picture gives it room)
        top = QtWidgets.QHBoxLayout()
        top.addLayout(camera, 3)
        figures = QtWidgets.QVBoxLayout()
        figures.addWidget(self.hr_label)
        figures.addWidget(self.rr_label)
        figures.addWidget(self.counters)
        figures.addStretch(1)
        top.addLayout(figures, 2)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addLayout(top, 3)
        layout.addWidget(self.plot, 2)
        layout.addWidget(self.follow_box)

    def _make_plot(self) -> pg.PlotWidget:
        plot = pg.PlotWidget(background="w")
        plot.setLabel("bottom", "session time", units="s")
        plot.setLabel("left", "heart rate (bpm)")
        plot.showGrid(x=True, y=True, alpha=0.2)
        plot.setYRange(50, 200)
        plot.setXRange(0, 60)
        plot.setMouseEnabled(x=True, y=True)  # zoom with the wheel, pan by dragging; 'follow live' returns
        plot.getViewBox().sigRangeChangedManually.connect(lambda *_: self.follow_box.setChecked(False))
        plot.setMinimumHeight(150)
        self.curve = plot.plot(pen=pg.mkPen("#c0002a", width=2))
        self.curve.setDownsampling(auto=True, method="peak")
        self.curve.setClipToView(True)
        return plot

    def _make_monitor(self) -> QtWidgets.QGroupBox:
        """The strap watched after Stop, in a small plot of its own (the big plot keeps the last recording)."""
        self.monitor_box = QtWidgets.QGroupBox("Live strap (not recording)")
        self.monitor_box.setToolTip("The strap watched since Stop, not recorded: the plot below keeps the last "
                                    "recording until the next Record")
        self.monitor_plot = pg.PlotWidget(background="w")
        self.monitor_plot.setLabel("left", "bpm")
        self.monitor_plot.setLabel("bottom", "strap time (s)")
        self.monitor_plot.setMouseEnabled(x=False, y=False)
        self.monitor_plot.hideButtons()
        self.monitor_plot.setFixedHeight(88)
        self.monitor_plot.setYRange(50, 200)
        self.monitor_curve = self.monitor_plot.plot(pen=pg.mkPen("#1f5fa8", width=2))
        box = QtWidgets.QVBoxLayout(self.monitor_box)
        box.setContentsMargins(4, 2, 4, 2)
        box.addWidget(self.monitor_plot)
        self._monitor: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))
        self.monitor_box.hide()
        return self.monitor_box

    def add_monitor_samples(self, t_s: np.ndarray, hr_bpm: np.ndarray) -> None:
        """Draw the strap watched (not recorded) in the live strap area, its last :data:`MONITOR_S` seconds
        (NaN: no contact, drawn as a gap), and show the area."""
        t = np.concatenate([self._monitor[0], np.asarray(t_s, dtype=float)])
        hr = np.concatenate([self._monitor[1], np.asarray(hr_bpm, dtype=float)])
        keep = t >= t[-1] - MONITOR_S if t.size else np.zeros(0, bool)
        self._monitor = (t[keep], hr[keep])
        self.monitor_curve.setData(*self._monitor, connect="finite")
        if t.size:  # the first minute fills from the left, then the last minute scrolls (no time before it)
            lo = max(float(self._monitor[0][0]), float(t[-1]) - MONITOR_S)
            self.monitor_plot.setXRange(lo, lo + MONITOR_S, padding=0.0)
        self.monitor_box.show()

    def clear_monitor(self) -> None:
        """Hide and empty the live strap area (a Record, or no strap watched)."""
        self._monitor = (np.empty(0), np.empty(0))
        self.monitor_curve.setData([], [])
        self.monitor_box.hide()

    def n_monitor_samples(self) -> int:
        """Valid samples in the live strap area (tests)."""
        return int(np.isfinite(self._monitor[1]).sum())

    def set_zones(self, hr_rest_bpm: float, hr_max_bpm: float) -> None:
        """Shade the HR zones for this participant's resting and maximal HR."""
        for item in self._zone_items:
            self.plot.removeItem(item)
        self._zone_items = []
        for (name, lo, hi), (*_, colour) in zip(hr_zones(hr_rest_bpm, hr_max_bpm), ZONES):
            brush = QtGui.QColor(colour)
            brush.setAlpha(60)
            item = pg.LinearRegionItem((lo, hi), orientation="horizontal", movable=False, brush=brush,
                                       pen=pg.mkPen(None))
            item.setZValue(-10)
            # anchored below the band's upper line: the label sits inside its own band
            pg.InfLineLabel(item.lines[1], name, position=0.985, anchors=[(1, 0), (1, 0)], color="#606060")
            self.plot.addItem(item)
            self._zone_items.append(item)
        self.plot.setYRange(hr_rest_bpm - 20, hr_max_bpm + 10)

    def add_samples(self, t_s: np.ndarray, hr_bpm: np.ndarray) -> None:
        """Append samples (session seconds, bpm; NaN for no contact or a gap: drawn as a gap, never
        a straight line across it) and redraw the last :data:`WINDOW_S` while following live."""
        if len(t_s) == 0:
            return
        self._t_s = np.concatenate([self._t_s, np.asarray(t_s, dtype=float)])
        self._hr_bpm = np.concatenate([self._hr_bpm, np.asarray(hr_bpm, dtype=float)])
        self.curve.setData(self._t_s, self._hr_bpm, connect="finite")
        if self.follow:
            self.scroll_to(float(self._t_s[-1]))

    def add_gap(self, t_s: float) -> None:
        """Break the curve at ``t_s`` (the strap was lost: no line across the gap)."""
        self.add_samples(np.array([t_s]), np.array([np.nan]))

    def scroll_to(self, t_s: float) -> None:
        """Show the window of :data:`WINDOW_S` ending at ``t_s`` (at least the first minute)."""
        self.plot.setXRange(max(0.0, t_s - WINDOW_S), max(60.0, t_s), padding=0.02)

    def set_follow(self, follow: bool) -> None:
        """Follow the live end of the recording (True), or keep the range the user zoomed to."""
        self.follow = follow
        self.follow_box.setChecked(follow)
        if follow and self._t_s.size:
            self.scroll_to(float(self._t_s[-1]))
            self.plot.getViewBox().enableAutoRange(y=False)

    def n_samples(self) -> int:
        """Valid samples drawn so far (gaps not counted)."""
        return int(np.isfinite(self._hr_bpm).sum())

    def add_marker(self, t_s: float, label: str, colour: str = "#404040") -> None:
        """Draw a phase or marker line at ``t_s`` with its label.

        A label goes on the highest row where no earlier label's text (its width at the current
        zoom) reaches ``t_s``, so close markers step down instead of overlapping.
        """
        span_s = max(60.0, float(np.diff(self.plot.viewRange()[0])[0]))
        s_per_px = span_s / max(200.0, float(self.plot.getViewBox().width()))
        near = {m.label_row for m in self._markers
                if m.value() - 1.0 * s_per_px * _CHAR_PX <= t_s <= m.value() + len(m.label.format) * _CHAR_PX * s_per_px}
        row = next((i for i in range(len(_LABEL_POSITIONS)) if i not in near), len(self._markers) % 6)
        # rows a text line apart whatever the plot's height
        step = max(0.08, _ROW_PX / max(100.0, float(self.plot.getViewBox().height())))
        position = max(0.05, _LABEL_POSITIONS[0] - row * step)
        line = pg.InfiniteLine(t_s, angle=90, pen=pg.mkPen(colour, style=QtCore.Qt.PenStyle.DashLine),
                               label=label, labelOpts={"position": position, "color": colour,
                                                       "anchors": [(0, 0.5), (0, 0.5)], "fill": "#ffffffc0"})
        line.label_row = row  # the row, for the next labels' layout
        self.plot.addItem(line)
        self._markers.append(line)

    def marker_labels(self) -> list[str]:
        """The labels of the lines drawn (tests, screenshots)."""
        return [m.label.format for m in self._markers]

    def set_current(self, hr_bpm: float | None, rr_ms: float | None) -> None:
        """Show the current HR and RR in large figures ('--' when unknown)."""
        self.hr_label.value.setText("--" if hr_bpm is None else f"{hr_bpm:.0f}")
        self.rr_label.value.setText("--" if rr_ms is None else f"{rr_ms:.0f}")

    def set_frame(self, frame_bgr: np.ndarray | None, caption: str = "") -> None:
        """Show a camera frame (H x W x 3 BGR uint8) with an optional caption, or the caption alone."""
        self.preview_caption.setText(caption)
        if frame_bgr is None:
            self.preview.setText("no camera")
            return
        rgb = np.ascontiguousarray(frame_bgr[..., ::-1])
        h, w = rgb.shape[:2]
        image = QtGui.QImage(rgb.data, w, h, 3 * w, QtGui.QImage.Format.Format_RGB888).copy()
        pix = QtGui.QPixmap.fromImage(image).scaled(
            self.preview.size(), QtCore.Qt.AspectRatioMode.KeepAspectRatio,
            QtCore.Qt.TransformationMode.SmoothTransformation)
        self.preview.setPixmap(pix)

    def set_counters(self, counters: dict[str, Any]) -> None:
        """Update the counters (keys of :data:`_Counters.ROWS`; missing keys keep their text)."""
        self.counters.update(counters)

    def clear(self) -> None:
        """Forget the plotted samples and markers (a new recording)."""
        self._t_s = np.empty(0)
        self._hr_bpm = np.empty(0)
        self.curve.setData([], [])
        for line in self._markers:
            self.plot.removeItem(line)
        self._markers = []
        self.set_current(None, None)
        self.plot.setXRange(0, 60)
        self.set_follow(True)


class _BigLabel(QtWidgets.QWidget):
    """A large number with its unit underneath."""

    def __init__(self, text: str, unit: str, point_size: int) -> None:
        super().__init__()
        self.value = QtWidgets.QLabel(text)
        font = self.value.font()
        font.setPointSize(point_size)
        font.setBold(True)
        self.value.setFont(font)
        self.value.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.unit = QtWidgets.QLabel(unit)
        self.unit.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(0)
        layout.addWidget(self.value)
        layout.addWidget(self.unit)


class _Counters(QtWidgets.QWidget):
    """A two-column grid of the recording counters."""

    ROWS = (("link", "Strap"), ("elapsed", "Elapsed"), ("rate", "Sample rate"), ("last", "Last sample"),
            ("contact", "Skin contact"), ("samples", "HR samples"),
            ("contact_loss", "Contact lost"), ("bad", "Bad frames"),
            ("frames", "Video frames"), ("dropped", "Dropped"), ("size", "On disk"))
    #: rows that take the whole width (their text is long)
    WIDE = ("link", "contact")

    def __init__(self) -> None:
        super().__init__()
        grid = QtWidgets.QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        grid.setHorizontalSpacing(8)
        grid.setVerticalSpacing(1)
        self.labels: dict[str, QtWidgets.QLabel] = {}
        row, col = 0, 0
        for key, text in self.ROWS:
            self.labels[key] = QtWidgets.QLabel("-")
            self.labels[key].setToolTip(text)
            if key in self.WIDE:
                row, col = (row + 1, 0) if col else (row, 0)
                grid.addWidget(QtWidgets.QLabel(text), row, 0)
                grid.addWidget(self.labels[key], row, 1, 1, 3)
                row += 1
                continue
            grid.addWidget(QtWidgets.QLabel(text), row, col)
            grid.addWidget(self.labels[key], row, col + 1)
            row, col = (row, 2) if col == 0 else (row + 1, 0)
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(3, 1)

    # shadows QWidget.update() (a repaint request, which nothing here calls) with the counters' update
    def update(self, counters: dict[str, Any]) -> None:  # type: ignore[override]  # see above
        """Set the text of the rows named in ``counters``."""
        for key, value in counters.items():
            if key in self.labels:
                self.labels[key].setText(str(value))
