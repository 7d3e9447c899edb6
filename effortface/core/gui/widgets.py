"""Small widgets shared by the stages: captions that wrap, labels and combo boxes that elide.

Both keep a stage's minimum width independent of its texts (long captions, file names, paths),
so that the stages fit a 1280 x 800 window beside the main window's stage list.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

__all__ = ["QtElidedComboBox", "QtElidedLabel", "caption", "elide_path"]


def caption(text: str, parent: QtWidgets.QWidget | None = None) -> QtWidgets.QLabel:
    """A label that word-wraps, so that its text never sets the width of its layout.

    Parameters
    ----------
    text : str
        Plain or rich text.
    parent : QWidget, optional
        Parent widget.

    Returns
    -------
    QLabel
    """
    label = QtWidgets.QLabel(text, parent)
    label.setWordWrap(True)
    return label


class QtElidedLabel(QtWidgets.QLabel):
    """A one-line label that elides its text when narrower than it; the tooltip holds the whole text.

    :meth:`text` still returns the whole text: only the painting is shortened.

    Parameters
    ----------
    text : str
        The text (plain).
    min_chars, max_chars : int
        Smallest width, and widest preferred width, in average characters (a layout shares the
        space left between such labels instead of giving it to the longest text).
    mode : Qt.TextElideMode
        Where the ellipsis goes (default: in the middle, which keeps a file name's end).
    parent : QWidget, optional
        Parent widget.
    """

    def __init__(self, text: str = "", min_chars: int = 12, max_chars: int = 48,
                 mode: QtCore.Qt.TextElideMode = QtCore.Qt.TextElideMode.ElideMiddle,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self._min_chars, self._max_chars = min_chars, max_chars
        self._mode = mode
        self.setTextFormat(QtCore.Qt.TextFormat.PlainText)
        self.setText(text)

    def setText(self, text: str) -> None:
        """Show ``text`` (elided when needed) and put it whole in the tooltip."""
        super().setText(text)
        self.setToolTip(text)

    def minimumSizeHint(self) -> QtCore.QSize:
        """At most ``min_chars`` characters wide, whatever the text."""
        return self._capped(super().minimumSizeHint(), self._min_chars)

    def sizeHint(self) -> QtCore.QSize:
        """The text's width, at most ``max_chars`` characters."""
        return self._capped(super().sizeHint(), self._max_chars)

    def _capped(self, hint: QtCore.QSize, chars: int) -> QtCore.QSize:
        width = self.fontMetrics().averageCharWidth() * chars + self.contentsMargins().left() \
            + self.contentsMargins().right()
        return QtCore.QSize(min(hint.width(), width), hint.height())

    def elided_text(self) -> str:
        """The text as painted at the current width."""
        return self.fontMetrics().elidedText(self.text(), self._mode, self.contentsRect().width())

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:
        """Paint the elided text with the label's palette (style sheet colours included)."""
        painter = QtGui.QPainter(self)
        self.style().drawItemText(painter, self.contentsRect(), int(self.alignment()), self.palette(),
                                  self.isEnabled(), self.elided_text(), self.foregroundRole())
        painter.end()


def elide_path(metrics: QtGui.QFontMetrics, path: str, width_px: int) -> str:
    """``path`` shortened to ``width_px``: its folders elided first, so the file name stays whole.

    Parameters
    ----------
    metrics : QFontMetrics
        The font the text is painted in.
    path : str
        A path, ``/`` or ``\\`` separated.
    width_px : int
        The room in pixels.

    Returns
    -------
    str
        ``path`` if it fits, else its folders elided in the middle before the whole file name (a
        file name wider than the room by itself is elided in the middle).
    """
    middle = QtCore.Qt.TextElideMode.ElideMiddle
    cut = max(path.rfind("/"), path.rfind("\\")) + 1  # after the last separator (0: none)
    folders, name = path[:cut], path[cut:]
    room = width_px - metrics.horizontalAdvance(name)  # for the folders, with their ellipsis
    if metrics.horizontalAdvance(path) <= width_px or not folders or room < metrics.horizontalAdvance("\u2026/"):
        return metrics.elidedText(path, middle, width_px)
    return metrics.elidedText(folders, middle, room) + name


class QtElidedComboBox(QtWidgets.QComboBox):
    """A combo box of file paths that shortens its current text to its width (:func:`elide_path`);
    the list that drops down shows the whole entries."""

    def elided_text(self) -> str:
        """The current text as painted at the current width."""
        option = QtWidgets.QStyleOptionComboBox()
        self.initStyleOption(option)
        field = self.style().subControlRect(QtWidgets.QStyle.ComplexControl.CC_ComboBox, option,
                                            QtWidgets.QStyle.SubControl.SC_ComboBoxEditField, self)
        return elide_path(self.fontMetrics(), self.currentText(), field.width())

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:
        """Paint the frame and arrow as usual, the text elided."""
        painter = QtWidgets.QStylePainter(self)
        option = QtWidgets.QStyleOptionComboBox()
        self.initStyleOption(option)
        painter.drawComplexControl(QtWidgets.QStyle.ComplexControl.CC_ComboBox, option)
        option.currentText = self.elided_text()
        painter.drawControl(QtWidgets.QStyle.ControlElement.CE_ComboBoxLabel, option)
