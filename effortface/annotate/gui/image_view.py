"""An image label for video frames and the face preview (numpy BGR -> QPixmap, aspect kept)."""

from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets


def bgr_to_qimage(image: np.ndarray) -> QtGui.QImage:
    """A QImage that owns a copy of a BGR ``uint8`` array of shape ``(h, w, 3)``."""
    rgb = np.ascontiguousarray(image[:, :, ::-1])
    h, w = rgb.shape[:2]
    return QtGui.QImage(rgb.data, w, h, 3 * w, QtGui.QImage.Format.Format_RGB888).copy()


class QtImageView(QtWidgets.QLabel):
    """Shows one BGR image scaled to the label's size, aspect ratio kept, with a caption below it.

    Parameters
    ----------
    placeholder : str
        Text shown before the first image.
    min_size : (int, int)
        Minimum width and height in pixels.
    """

    def __init__(self, placeholder: str, min_size: tuple[int, int] = (240, 180),
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(placeholder, parent)
        self.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        self.setMinimumSize(*min_size)
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Expanding)
        self.setStyleSheet("background:#202020; color:#d0d0d0;")
        self._image: QtGui.QImage | None = None
        self.overlay = ""

    def set_overlay(self, text: str) -> None:
        """Text drawn over the image's bottom-left corner (the video's timecode)."""
        if text != self.overlay:
            self.overlay = text
            self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802 - Qt override
        super().paintEvent(event)
        if not self.overlay:
            return
        painter = QtGui.QPainter(self)
        font = painter.font()
        font.setFamily("monospace")
        font.setPointSize(max(font.pointSize(), 10))
        painter.setFont(font)
        box = painter.fontMetrics().boundingRect(self.overlay).adjusted(-6, -3, 6, 3)
        box.moveBottomLeft(self.contentsRect().bottomLeft() + QtCore.QPoint(6, -6))
        painter.fillRect(box, QtGui.QColor(0, 0, 0, 170))
        painter.setPen(QtGui.QColor("#ffffff"))
        painter.drawText(box, QtCore.Qt.AlignmentFlag.AlignCenter, self.overlay)
        painter.end()

    def set_image(self, image: np.ndarray) -> None:
        """Show a BGR array."""
        self._image = bgr_to_qimage(image)
        self._rescale()

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt override
        super().resizeEvent(event)
        self._rescale()

    def _rescale(self) -> None:
        if self._image is None:
            return
        size = self.contentsRect().size()
        pixmap = QtGui.QPixmap.fromImage(self._image).scaled(
            size, QtCore.Qt.AspectRatioMode.KeepAspectRatio, QtCore.Qt.TransformationMode.SmoothTransformation)
        self.setPixmap(pixmap)
