"""Opening a real USB ANT stick as an ANT+ heart-rate receiver (slave channel, device type 120).

:func:`open_sequence` returns the framed messages to write, in order, after opening the serial port
(the link waits for each channel response ``A4 03 40 <ch> <msg id> 00`` before the next, or simply
paces them). The ANT+ network key is never part of this repository: :func:`load_network_key` reads
it from the environment variable ``EFFORTFACE_ANT_NETWORK_KEY`` or, failing that, from the user's
config file ``$XDG_CONFIG_HOME/effortface/config.ini`` (default ``~/.config/effortface/config.ini``)::

    [ant]
    network_key = B9 A5 21 FB BD 72 C3 45

The key is 8 bytes written as 16 hex digits; spaces, commas, colons and ``0x`` prefixes are allowed.
Decoding and replaying recorded bytes never need it.
"""

from __future__ import annotations

import configparser
import os
import re
from collections.abc import Mapping
from pathlib import Path

from effortface.core.errors import DeviceError, DeviceErrorReason, UserError
from effortface.capture_tool.protocols.ant import HRM_DEVICE_TYPE, MSG_OPEN_CHANNEL
from effortface.capture_tool.protocols.encode import encode_ant_frame

ENV_VAR = "EFFORTFACE_ANT_NETWORK_KEY"
CONFIG_SECTION, CONFIG_KEY = "ant", "network_key"
MSG_RESET, MSG_NETWORK_KEY, MSG_ASSIGN, MSG_CHANNEL_ID = 0x4A, 0x46, 0x42, 0x51
MSG_PERIOD, MSG_RF_FREQ = 0x43, 0x45
CHANNEL_SLAVE = 0x00  # bidirectional receive (slave) channel
HRM_PERIOD_1_32768_S = 8070  # 4.06 Hz, the ANT+ HRM message period
ANT_PLUS_RF_MHZ_OFFSET = 57  # 2457 MHz
_HEX_RE = re.compile(r"(?:0x)?([0-9a-fA-F]{2})")


def open_sequence(
    network_key: bytes,
    *,
    channel: int = 0,
    network: int = 0,
    device_number: int = 0,
    device_type: int = HRM_DEVICE_TYPE,
    trans_type: int = 0,
    period: int = HRM_PERIOD_1_32768_S,
    rf_freq: int = ANT_PLUS_RF_MHZ_OFFSET,
) -> list[bytes]:
    """Framed messages that reset a stick and open a heart-rate receive channel.

    Parameters
    ----------
    network_key : bytes
        The 8-byte ANT+ network key (see :func:`load_network_key`).
    channel, network : int
        Channel and network numbers.
    device_number : int
        Device to pair with; 0 is the wildcard (first heart-rate strap found).
    device_type, trans_type : int
        Channel id: 120 = heart-rate monitor; transmission type 0 = wildcard.
    period : int
        Channel period in 1/32768 s (8070 for ANT+ HRM).
    rf_freq : int
        RF channel, MHz above 2400 (57 for ANT+).

    Returns
    -------
    list of bytes
        Reset, set network key, assign channel, channel id, period, RF frequency, open channel.
    """
    if len(network_key) != 8:
        raise ValueError(f"network_key: expected 8 bytes, found {len(network_key)}")
    return [
        encode_ant_frame(MSG_RESET, b"\x00"),
        encode_ant_frame(MSG_NETWORK_KEY, bytes([network]) + bytes(network_key)),
        encode_ant_frame(MSG_ASSIGN, bytes([channel, CHANNEL_SLAVE, network])),
        encode_ant_frame(
            MSG_CHANNEL_ID,
            bytes([channel]) + device_number.to_bytes(2, "little") + bytes([device_type, trans_type]),
        ),
        encode_ant_frame(MSG_PERIOD, bytes([channel]) + period.to_bytes(2, "little")),
        encode_ant_frame(MSG_RF_FREQ, bytes([channel, rf_freq])),
        encode_ant_frame(MSG_OPEN_CHANNEL, bytes([channel])),
    ]


def parse_network_key(text: str, source: str) -> bytes:
    """Parse 16 hex digits (spaces, commas, colons, ``0x`` allowed) into 8 bytes.

    Raises
    ------
    UserError
        Naming ``source`` and what was found, if the text is not 8 hex bytes.
    """
    cleaned = re.sub(r"[\s,:;]+", " ", text.strip())
    parts = _HEX_RE.findall(cleaned)
    leftover = _HEX_RE.sub("", cleaned).replace(" ", "")
    if len(parts) != 8 or leftover:
        shown = f"{len(parts)} hex bytes" + (f" and {leftover[:12]!r}" if leftover else "")
        raise UserError(f"{source}: expected an ANT+ network key of 16 hex digits "
                        f"(e.g. '00 11 22 33 44 55 66 77'), found {shown}")
    return bytes(int(p, 16) for p in parts)


def config_path(environ: Mapping[str, str] | None = None) -> Path:
    """The user config file: ``$XDG_CONFIG_HOME/effortface/config.ini`` (``~/.config`` default)."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "effortface" / "config.ini"


def load_network_key(environ: Mapping[str, str] | None = None, path: Path | None = None) -> bytes:
    """The ANT+ network key, from ``EFFORTFACE_ANT_NETWORK_KEY`` or the user config file.

    Parameters
    ----------
    environ : mapping, optional
        Environment to read (default ``os.environ``).
    path : Path, optional
        Config file to read (default :func:`config_path`).

    Returns
    -------
    bytes
        8 bytes.

    Raises
    ------
    DeviceError
        ``reason=NO_KEY`` if neither gives a key; the message says how to get and store one.
    UserError
        If the key found is not 16 hex digits.
    """
    env = os.environ if environ is None else environ
    if env.get(ENV_VAR, "").strip():
        return parse_network_key(env[ENV_VAR], ENV_VAR)
    path = config_path(env) if path is None else path
    if path.is_file():
        parser = configparser.ConfigParser()
        try:
            parser.read(path, encoding="utf-8")
        except configparser.Error as exc:
            raise UserError(f"{path}: expected an INI file, found a syntax error ({exc})") from None
        text = parser.get(CONFIG_SECTION, CONFIG_KEY, fallback="").strip()
        if text:
            return parse_network_key(text, f"{path} [{CONFIG_SECTION}] {CONFIG_KEY}")
    raise DeviceError(
        f"ANT stick: no ANT+ network key found in ${ENV_VAR} or {path}; get the key with a free "
        f"ANT+ Adopter registration at https://www.thisisant.com, then set {ENV_VAR}='XX XX XX XX "
        f"XX XX XX XX' or write '[{CONFIG_SECTION}]' / '{CONFIG_KEY} = ...' in {path}",
        reason=DeviceErrorReason.NO_KEY,
    )
