"""One strap status (Qt-free): the single state behind Capture's Strap line, its banner and HR readout.

Before Record the pre-flight checks the chosen port, the live monitor watches it and Detect may
change the protocol; each of those feeds :class:`StrapStatus`, and the screen draws only its
:meth:`StrapStatus.view`, so the Strap line, the banner and the heart-rate readout cannot disagree:
a port another program holds is never "ready", bytes that do not decode name the protocol
("bytes arrive but none decode as ANT: try Detect"), and a problem's banner goes when its cause
does (another port, a protocol detected, the strap back). :func:`plain_link_error` turns pyserial's
messages into words a lab user reads.
"""

from __future__ import annotations

import dataclasses
import re

from effortface.capture_tool.monitor import MonitorStats

#: the states, from nothing chosen to a live heart rate
STATES = ("none", "checking", "opens", "live", "no_contact", "no_decode", "lost", "busy", "missing", "failed")
#: states that are a problem (red line, a banner)
PROBLEMS = ("no_decode", "lost", "busy", "missing", "failed")
#: bytes received without one decoded sample before the protocol is named as the likely cause
NO_DECODE_BYTES = 64

#: pyserial / OS message fragments -> plain words (first match wins)
_PLAIN = (
    (r"No such file|\[Errno 2\]|found no such device|could not open port .*FileNotFound",
     "no such device: the receiver is unplugged, or another port is meant"),
    (r"Permission denied|\[Errno 13\]|permission",
     "permission denied: add this user to the 'dialout' group, then log in again"),
    (r"Device or resource busy|\[Errno 16\]|exclusively lock|in use by another program",
     "in use by another program: close it (or the other effortface window) and choose the port again"),
    (r"returned no data|device disconnected or multiple access|Input/output error|\[Errno 5\]|"
     r"\[Errno 19\]|No such device",
     "the receiver stopped answering: it was unplugged or lost power"),
    (r"timed? ?out|Timeout", "the receiver did not answer in time"),
)


def plain_link_error(message: str) -> str:
    """A strap/serial error in words a lab user reads (the port, if named, kept in front).

    Parameters
    ----------
    message : str
        pyserial's or the link's message, e.g. ``"device reports readiness to read but returned no
        data (device disconnected or multiple access on port?)"``.

    Returns
    -------
    str
        One line; the original first line if no plain wording is known.
    """
    first = message.strip().splitlines()[0] if message.strip() else "unknown error"
    named = re.match(r"(?:--port )?(\S*[/:]\S*?): ", first)
    prefix = f"{named.group(1)}: " if named else ""
    for pattern, words in _PLAIN:
        if re.search(pattern, first, re.IGNORECASE):
            return prefix + words
    return first


@dataclasses.dataclass(frozen=True)
class StrapView:
    """What the screen shows for the strap, all from one state.

    Attributes
    ----------
    state : str
        One of :data:`STATES`.
    line : str
        The Strap line's text after its mark (``ready``, ``missing``...).
    ok : bool or None
        True: green tick; False: red cross; None: pending (checking, waiting for data).
    banner : str
        The banner's text, '' when the strap has nothing to say.
    hr_bpm : float or None
        The heart rate to show (None: '--', and :attr:`line` says why).
    """

    state: str
    line: str
    ok: bool | None
    banner: str
    hr_bpm: float | None


class StrapStatus:
    """The strap's one state before Record, fed by the pre-flight check, the monitor and Detect."""

    def __init__(self) -> None:
        self.port = ""
        self.protocol = ""
        self.state = "none"
        self.detail = ""
        self.hr_bpm: float | None = None

    # ----------------------------------------------------------------------------- inputs
    def choose(self, port: str, protocol: str) -> None:
        """A port and protocol were chosen: what was said about the previous ones is forgotten."""
        if (port, protocol) != (self.port, self.protocol) or self.state in ("none",):
            self.port, self.protocol = port, protocol
            self._set("checking" if port else "none", "")

    def checking(self) -> None:
        """The chosen port is being opened again (a problem said before stays until the answer)."""
        if self.state in ("none", "checking"):
            self._set("checking", "")

    def opened(self) -> None:
        """The chosen port opens (or this application already holds it): waiting for heart rate."""
        if self.state not in ("live", "no_contact", "no_decode"):
            self._set("opens", "")

    def failed(self, message: str) -> None:
        """The port could not be opened or watched (``message``: the raw error)."""
        plain = plain_link_error(message)
        state = ("busy" if "in use" in plain else "missing" if "no such device" in plain or "unplugged" in plain
                 else "failed")
        self._set(state, plain)

    def detected(self, protocol: str | None) -> None:
        """Detect ran: ``protocol`` was found (the old protocol's problem goes) or None (not recognised)."""
        if protocol is None:
            self.detail = ("protocol not recognised from its bytes (polled straps such as HRMI cannot be "
                           "detected)")
            return
        self.protocol = protocol
        if self.state in ("no_decode", "live", "no_contact"):
            self._set("opens", "")
        self.detail = f"detected protocol: {protocol}"

    def watched(self, stats: MonitorStats | None) -> None:
        """The live monitor's latest figures (None: not watched now)."""
        if stats is None:
            if self.state in ("live", "no_contact", "no_decode", "lost"):
                self._set("opens", "")
            return
        if stats.link_state == "reconnecting":
            self._set("lost", f"{stats.port}: strap lost (receiver unplugged?): reconnecting by itself")
        elif stats.samples_total == 0 and stats.bytes_in >= NO_DECODE_BYTES:
            self._set("no_decode", f"bytes arrive but none decode as {self.protocol.upper()}: try Detect")
        elif stats.hr_bpm is not None:
            self._set("live", "", stats.hr_bpm)
        elif stats.contact_now is False:
            self._set("no_contact", "no skin contact: moisten the strap and tighten it")
        elif self.state not in PROBLEMS or self.state in ("lost", "no_decode"):
            self._set("opens", "")

    def _set(self, state: str, detail: str, hr_bpm: float | None = None) -> None:
        self.state, self.detail, self.hr_bpm = state, detail, hr_bpm

    # ----------------------------------------------------------------------------- output
    def view(self) -> StrapView:
        """The Strap line, banner and HR readout for the current state."""
        port, state, detail = self.port, self.state, self.detail
        if state == "none":
            return StrapView(state, "missing: no port chosen", False, "", None)
        if state == "checking":
            return StrapView(state, f"checking... {port}", None, "", None)
        if state == "opens":
            note = f"{port} opens; waiting for heart rate ({self.protocol})"
            return StrapView(state, f"ready: {note}" + (f"; {detail}" if detail else ""), True, "", None)
        if state == "live":
            return StrapView(state, f"ready: {port}: live heart rate shown ({self.protocol})", True, "", self.hr_bpm)
        if state == "no_contact":
            return StrapView(state, f"ready: {port}: {detail}", None, "", None)
        banner = f"Strap {port}: {detail}" if not detail.startswith(port) else f"Strap {detail}"
        return StrapView(state, f"{'missing' if state != 'no_decode' else 'no heart rate'}: {detail}", False,
                         banner, None)
