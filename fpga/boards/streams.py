"""What the board's stream components pass each other: the layouts of a control record, a parsed
header and a byte of a record on its way out, and the link's two CRCs (``amaranth.lib.crc``'s,
the same as :func:`.protocol.crc16` and :func:`.protocol.crc32`)."""

from __future__ import annotations

from amaranth.hdl import unsigned
from amaranth.lib import data
from amaranth.lib.crc import catalog

from . import protocol as pr

__all__ = ["CRC16", "CRC32", "header_layout", "packet_layout", "record_layout"]

# CRC-16/CCITT-FALSE of the control records, and zlib's CRC-32 of the pixels and of the results.
CRC16 = catalog.CRC16_CCITT_FALSE(data_width=8)
CRC32 = catalog.CRC32_ISO_HDLC(data_width=8)


def record_layout() -> data.StructLayout:
    """A control record without its sync and CRC: its type, sequence number and payload."""
    return data.StructLayout({"type": unsigned(8), "seq": unsigned(8),
                              "payload": unsigned(8 * pr.PAYLOAD_BYTES)})


def header_layout() -> data.StructLayout:
    """A control record received: :func:`record_layout`'s fields and whether its CRC matched."""
    return data.StructLayout({"record": record_layout(), "crc_ok": unsigned(1)})


def packet_layout() -> data.StructLayout:
    """One byte of a record going out, ``last`` on the record's last byte (records are sent whole)."""
    return data.StructLayout({"data": unsigned(8), "last": unsigned(1)})
