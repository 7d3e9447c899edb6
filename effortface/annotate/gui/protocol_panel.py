"""The paper's protocol panel: one blendshape at a time in the fixed order, and its weight.

:class:`QtProtocolPanel` views an :class:`~effortface.annotate.annotate_session.AnnotateSession`: the blendshape
list in annotation order (the current one highlighted, finished passes ticked), the next blendshape
offered after a pass, a slider and a number box for the weight at the current frame (setting either
sets a key), the interpolation of the key, Set / Delete key buttons and the four current weights.
"""

from __future__ import annotations

import math

from PySide6 import QtCore, QtWidgets

from effortface.annotate.keyframes import INTERPOLATIONS
from effortface.annotate.annotate_session import AnnotateSession

HELP_TEXT = ("\u2190/\u2192 one frame (Shift: ten) \u00b7 Home/End \u00b7 0-9 key at weight 0.0-0.9, "
             "M at 1.0 \u00b7 \u2191/\u2193 weight \u00b10.05 \u00b7 K key at the box's weight \u00b7 "
             "Del delete key \u00b7 Space play/pause \u00b7 N next blendshape \u00b7 Ctrl+Z/Ctrl+Y undo/redo "
             "\u00b7 Ctrl+C/Ctrl+V copy/paste \u00b7 Ctrl+G go to frame \u00b7 Ctrl+A / Shift+click select keys, "
             "Alt+arrows move them, [ ] scale \u00b7 +/- zoom, F frame all \u00b7 L loop")
_TICK = "  \u2713 pass done"
_NEXT_READY = "QPushButton { background:#ffd870; font-weight:bold; }"


class WheelGuard(QtCore.QObject):
    """Event filter: a watched widget ignores the mouse wheel unless it has the keyboard focus.

    So scrolling past the weight box, slider or interpolation list never sets a key. The wheel
    event is ignored (not eaten) so a scrollable parent still scrolls.
    """

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        """Stop a wheel event for an unfocused watched widget; let everything else through."""
        if event.type() == QtCore.QEvent.Type.Wheel and isinstance(watched, QtWidgets.QWidget) \
                and not watched.hasFocus():
            event.ignore()
            return True
        return False


class QtProtocolPanel(QtWidgets.QWidget):
    """Blendshape order, weight slider and number, interpolation, key buttons (see module docstring).

    Parameters
    ----------
    session : AnnotateSession
        The rater's session.
    """

    def __init__(self, session: AnnotateSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self._updating = False
        self._build()
        session.frame_changed.connect(lambda *_: self.refresh())
        session.keys_changed.connect(lambda *_: self.refresh())
        session.blendshape_changed.connect(lambda *_: self.refresh())
        session.passes_changed.connect(lambda *_: self.refresh())
        self.refresh()

    def _build(self) -> None:
        self.shapes = QtWidgets.QListWidget()
        self.shapes.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        for i, name in enumerate(self.session.blendshape_names, start=1):
            self.shapes.addItem(f"{i}. {name}")
        self.shapes.setVerticalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.shapes.currentRowChanged.connect(self._on_row)
        self.drives = QtWidgets.QLabel(wordWrap=True)
        self.next_button = QtWidgets.QPushButton("Next blendshape (N)")
        self.next_button.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.next_button.clicked.connect(self.session.start_next_pass)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.slider.setRange(0, 100)
        self.slider.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.slider.sliderReleased.connect(lambda: self._set_weight(self.slider.value() / 100))
        self.slider.valueChanged.connect(self._on_slider_value)
        self.number = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=1.0, singleStep=0.01, decimals=2)
        self.number.setKeyboardTracking(False)
        self.number.valueChanged.connect(self._on_number)
        self.interp = QtWidgets.QComboBox()
        self.interp.addItems(INTERPOLATIONS)
        self.interp.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.interp.currentTextChanged.connect(self._on_interp)
        self.set_button = QtWidgets.QPushButton("Set key (K)")
        self.delete_button = QtWidgets.QPushButton("Delete key (Del)")
        for b in (self.set_button, self.delete_button):
            b.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.set_button.clicked.connect(lambda: self._set_weight(self.number.value()))
        self.delete_button.clicked.connect(lambda: self.session.delete_key())
        self.key_state = QtWidgets.QLabel()
        self.readout = QtWidgets.QLabel()
        self.readout.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self._guard_wheel()
        self._lay_out()

    def _guard_wheel(self) -> None:
        """The wheel edits the weight box only once it was clicked or tabbed into (slider, list: never)."""
        self.number.setFocusPolicy(QtCore.Qt.FocusPolicy.StrongFocus)
        self._wheel_guard = WheelGuard(self)
        for widget in (self.number, self.slider, self.interp):
            widget.installEventFilter(self._wheel_guard)

    def _lay_out(self) -> None:
        weight_row = QtWidgets.QHBoxLayout()
        weight_row.addWidget(self.slider, 1)
        weight_row.addWidget(self.number)
        form = QtWidgets.QFormLayout()
        form.addRow("Weight", weight_row)
        form.addRow("Interpolation", self.interp)
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(self.set_button)
        buttons.addWidget(self.delete_button)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 0, 4, 0)
        layout.setSpacing(4)  # with the list as tall as its rows, the panel fits a 1280x800 screen unscrolled
        form.setVerticalSpacing(4)
        layout.addWidget(QtWidgets.QLabel("<b>Blendshapes, in keying order</b>"))
        layout.addWidget(self.shapes)
        layout.addWidget(self.drives)
        layout.addWidget(self.next_button)
        layout.addLayout(form)
        layout.addLayout(buttons)
        layout.addWidget(self.key_state)
        layout.addWidget(self.readout)
        layout.addStretch(1)

    # --------------------------------------------------------------------------- from the model
    def refresh(self) -> None:
        """Show the model's current blendshape, weight, key and passes."""
        self._updating = True
        m = self.session
        row = m.blendshape_names.index(m.blendshape)
        for i, name in enumerate(m.blendshape_names):
            item = self.shapes.item(i)
            item.setText(f"{i + 1}. {name}" + (_TICK if name in m.passes_done else ""))
            font = item.font()
            font.setBold(i == row)
            item.setFont(font)
        self.shapes.setCurrentRow(row)
        self._fit_shapes()
        shape = m.annotations.blendshapes.shapes[row]
        self.drives.setText(f"Keying <b>{shape.name}</b>: {shape.drives}")
        self._refresh_next()
        weight = m.weight()
        shown = 0.0 if math.isnan(weight) else weight
        self.slider.setValue(round(shown * 100))
        self.number.setValue(shown)
        key = m.key_at()
        self.interp.setCurrentText(key.interp if key else m.interp)
        self.key_state.setText(f"Key on frame {m.frame}" if key else f"No key on frame {m.frame}"
                               + (" (not keyed yet)" if math.isnan(weight) else " (interpolated)"))
        self.delete_button.setEnabled(key is not None)
        self.readout.setText(self._readout())
        self._updating = False

    def _fit_shapes(self) -> None:
        """The blendshape list exactly as tall as its rows: no empty band, no scrolling."""
        rows = sum(self.shapes.sizeHintForRow(i) for i in range(self.shapes.count()))
        self.shapes.setFixedHeight(rows + 2 * self.shapes.frameWidth())

    def _refresh_next(self) -> None:
        nxt = self.session.next_blendshape
        done = self.session.blendshape in self.session.passes_done
        self.next_button.setEnabled(nxt is not None)
        self.next_button.setText(f"Next: {nxt} (N)" if nxt else "Last blendshape")
        self.next_button.setStyleSheet(_NEXT_READY if done and nxt else "")
        self.next_button.setToolTip("Pass done: go on with the next blendshape from frame 0" if done else
                                    "Key this blendshape over the whole video first (the paper's protocol)")

    def _readout(self) -> str:
        """Every blendshape's weight at this frame, two to a row (the current one in blue)."""
        cells = []
        for name, w in self.session.weights().items():
            text = "-" if math.isnan(w) else f"{w:.2f}"
            style = " style='color:#1f5fbf'" if name == self.session.blendshape else ""
            cells.append(f"<td{style}>{name}</td><td{style} align='right'>&nbsp;{text}&nbsp;&nbsp;&nbsp;</td>")
        rows = ("<tr>" + "".join(cells[i:i + 2]) + "</tr>" for i in range(0, len(cells), 2))
        return "<b>Weights at this frame</b><table cellspacing='0'>" + "".join(rows) + "</table>"

    # ----------------------------------------------------------------------------- to the model
    def _set_weight(self, weight: float) -> None:
        self.session.set_key(round(float(weight), 2))

    def _on_slider_value(self, value: int) -> None:
        if self._updating:
            return
        if self.slider.isSliderDown():
            self.number.blockSignals(True)
            self.number.setValue(value / 100)  # preview while dragging; the key is set on release
            self.number.blockSignals(False)
        else:
            self._set_weight(value / 100)

    def _on_number(self, value: float) -> None:
        if not self._updating:
            self._set_weight(value)

    def _on_interp(self, interp: str) -> None:
        if not self._updating:
            self.session.set_interp(interp)

    def _on_row(self, row: int) -> None:
        if not self._updating and row >= 0:
            self.session.set_blendshape(self.session.blendshape_names[row])

    def sizeHint(self) -> QtCore.QSize:  # noqa: N802 - Qt override
        return QtCore.QSize(280, super().sizeHint().height())

