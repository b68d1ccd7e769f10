"""The Open Driver INIT data block: the DB189 vector, every code table, every SYSTAT refusal."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest

from prc3cfg.core.gateway import (
    GatewayRefused,
    GatewaySettings,
    Refusal,
    format_data_block,
    init_data_block,
    refusals,
)
from prc3cfg.core.line import LineSettings
from prc3cfg.errors import UserError

# seed 004 §10.3.2, interface 0: DB 30 from DW 1, all CPUs, identifier 1, 9600 8E1, ZVZ 220 ms.
DB189 = GatewaySettings(receive_db=30, receive_dw=1, cpu=0, identifier=1,
                        line=LineSettings(9600, 8, "even", 1), zvz_ms=220)
DB189_WORDS = (0x1E01, 0x0001, 0x0034, 0x0000, 0x0000, 0x0000, 220, 0x0000)
DB189_LISTING = [
    ("DW 1", "KY = 030,001", "1E01h"),
    ("DW 2", "KY = 000,001", "0001h"),
    ("DW 3", "KM = 00000000 00110100", "0034h"),
    ("DW 4", "KM = 00000000 00000000", "0000h"),
    ("DW 5", "KH = 0000", "0000h"),
    ("DW 6", "KH = 0000", "0000h"),
    ("DW 7", "KF = +220", "00DCh"),
    ("DW 8", "KH = 0000", "0000h"),
]


def with_line(**line) -> GatewaySettings:
    return replace(DB189, line=replace(DB189.line, **line))


def test_db189_words():
    assert refusals(DB189) == []
    assert init_data_block(DB189) == DB189_WORDS


def test_db189_listing():
    assert format_data_block(init_data_block(DB189)) == DB189_LISTING


# ---- PROPAM (DW 3) ---------------------------------------------------------------------

@pytest.mark.parametrize("baud, code", [
    (19200, 0b0011), (9600, 0b0100), (4800, 0b0101), (2400, 0b0110), (1200, 0b0111),
    (600, 0b1000), (300, 0b1001), (200, 0b1010), (150, 0b1011), (110, 0b1100),
    (75, 0b1101), (50, 0b1111),
])
def test_baud_codes(baud, code):
    assert init_data_block(with_line(baud=baud))[2] == 0x0030 | code


@pytest.mark.parametrize("parity, code", [("none", 0b00), ("odd", 0b10), ("even", 0b11)])
def test_parity_codes(parity, code):
    assert init_data_block(with_line(parity=parity))[2] == code << 4 | 0b0100


@pytest.mark.parametrize("stop_bits, code", [(1, 0b00), (1.5, 0b01), (2, 0b10)])
def test_stop_bit_codes(stop_bits, code):
    assert init_data_block(with_line(stop_bits=stop_bits))[2] == code << 6 | 0x34


@pytest.mark.parametrize("data_bits, code", [(8, 0b00), (7, 0b01), (6, 0b10), (5, 0b11)])
def test_data_bit_codes(data_bits, code):
    assert init_data_block(with_line(data_bits=data_bits))[2] == code << 8 | 0x34


def test_propam_all_fields_together():
    word = init_data_block(with_line(baud=1200, data_bits=7, parity="odd", stop_bits=2))[2]
    assert word == 0b01_10_10_0111
    assert format_data_block((0,) * 2 + (word,) + (0,) * 5)[2][1] == "KM = 00000001 10100111"


# ---- PROPAR (DW 4) and the other words -------------------------------------------------

@pytest.mark.parametrize("options, word", [
    ({"break_evaluation_off": True}, 1 << 1),
    ({"rs485": True, "break_evaluation_off": True}, 0b0110),    # §5.2.5.2 default for RS485
    ({"xon_xoff_receive": True}, 1 << 8),
    ({"xon_xoff_output": True, "xoff_ms": 4}, 1 << 9),
    ({"end_criterion": "one-end-char"}, 0b01 << 10),
    ({"end_criterion": "two-end-chars"}, 0b10 << 10),
    ({"end_criterion": "fixed-length", "telegram_length": 64}, 0b11 << 10),
    ({"echo": True}, 1 << 12),
    ({"keep_free_after_stx": True}, 1 << 13),
    ({"full_duplex": True}, 1 << 14),
    ({"trailing_ff": True}, 1 << 15),
])
def test_propar_bits(options, word):
    assert init_data_block(replace(DB189, **options))[3] == word


@pytest.mark.parametrize("options, dw, word, notation", [
    ({"end_criterion": "two-end-chars", "end_chars": (0x0D, 0x0A)}, 5, 0x0D0A, "KH = 0D0A"),
    ({"telegram_length": 128}, 6, 128, "KF = +128"),
    ({"telegram_length": 1024}, 6, 1024, "KF = +1024"),
    ({"zvz_ms": 4}, 7, 4, "KF = +4"),
    ({"zvz_ms": 65535}, 7, 0xFFFF, "KH = FFFF"),             # above KF's +32767
    ({"xon_xoff_output": True, "xoff_ms": 2000}, 8, 2000, "KF = +2000"),
    ({"receive_db": 255, "receive_dw": 255}, 1, 0xFFFF, "KY = 255,255"),
    ({"cpu": 4, "identifier": 223}, 2, 0x04DF, "KY = 004,223"),
])
def test_other_words(options, dw, word, notation):
    words = init_data_block(replace(DB189, **options))
    assert words[dw - 1] == word
    assert format_data_block(words)[dw - 1] == (f"DW {dw}", notation, f"{word:04X}h")


# ---- refusals: one case per SYSTAT -----------------------------------------------------

@pytest.mark.parametrize("options, systat, field", [
    ({"line": LineSettings(baud=38400)}, 0x8B, "line.baud"),
    ({"line": LineSettings(baud=1000)}, 0x8B, "line.baud"),
    ({"line": LineSettings(baud=19200), "interface": "tty"}, 0x8B, "line.baud"),
    ({"line": LineSettings(baud=19200), "full_duplex": True}, 0x8B, "line.baud"),
    ({"line": SimpleNamespace(baud=9600, data_bits=8, parity="mark", stop_bits=1)},
     0x8C, "line.parity"),
    ({"full_duplex": True, "echo": True}, 0x8D, "echo"),
    ({"full_duplex": True, "xon_xoff_receive": True}, 0x8D, "xon_xoff_receive"),
    ({"full_duplex": True, "xon_xoff_output": True, "xoff_ms": 100}, 0x8D, "xon_xoff_output"),
    ({"full_duplex": True, "keep_free_after_stx": True}, 0x8D, "keep_free_after_stx"),
    ({"zvz_ms": 3}, 0x8E, "zvz_ms"),
    ({"zvz_ms": 0}, 0x8E, "zvz_ms"),
    ({"receive_db": 2}, 0x8F, "receive_db"),
    ({"cpu": 5}, 0x90, "cpu"),
    ({"identifier": 0}, 0x91, "identifier"),
    ({"identifier": 224}, 0x91, "identifier"),
    ({"telegram_length": 1025}, 0x92, "telegram_length"),
    ({"end_criterion": "fixed-length"}, 0x92, "telegram_length"),
    ({"rs485": True}, 0x93, "break_evaluation_off"),
    ({"rs485": True, "break_evaluation_off": True, "echo": True}, 0x93, "echo"),
    ({"rs485": True, "break_evaluation_off": True, "xon_xoff_receive": True},
     0x93, "xon_xoff_receive"),
    ({"rs485": True, "break_evaluation_off": True, "xon_xoff_output": True, "xoff_ms": 100},
     0x93, "xon_xoff_output"),
    ({"rs485": True, "break_evaluation_off": True, "keep_free_after_stx": True},
     0x93, "keep_free_after_stx"),
    ({"rs485": True, "break_evaluation_off": True, "full_duplex": True}, 0x93, "full_duplex"),
    ({"rs485": True, "break_evaluation_off": True, "interface": "v24"}, 0x94, "interface"),
    ({"rs485": True, "break_evaluation_off": True, "interface": "tty"}, 0x94, "interface"),
    ({"xon_xoff_output": True, "xoff_ms": 3}, 0x95, "xoff_ms"),
])
def test_single_refusal(options, systat, field):
    settings = replace(DB189, **options)
    [refusal] = refusals(settings)
    assert (refusal.systat, refusal.field) == (systat, field)
    assert str(refusal).startswith(f"SYSTAT {systat:02X}h: ")
    with pytest.raises(GatewayRefused) as raised:
        init_data_block(settings)
    assert raised.value.refusals == (refusal,)
    assert str(refusal) in str(raised.value)
    assert isinstance(raised.value, UserError)


def test_zvz_3_ms_reason():
    assert [str(r) for r in refusals(replace(DB189, zvz_ms=3))] == [
        "SYSTAT 8Eh: character delay time ZVZ 3 ms is below the driver's minimum of 4 ms"]


@pytest.mark.parametrize("options", [
    {"line": LineSettings(baud=19200), "interface": "rs422"},
    {"line": LineSettings(baud=19200), "interface": "v24"},
    {"line": LineSettings(baud=9600), "interface": "tty", "full_duplex": True},
    {"xoff_ms": 0},                                            # XOFFTIM unread without bit 9
    {"telegram_length": 0, "end_criterion": "one-end-char", "end_chars": (0x03, 0)},
    {"rs485": True, "break_evaluation_off": True},
])
def test_accepted(options):
    assert refusals(replace(DB189, **options)) == []


def test_several_refusals_in_systat_order():
    settings = replace(DB189, xon_xoff_output=True, xoff_ms=1, identifier=0, cpu=7,
                       receive_db=0, zvz_ms=2, full_duplex=True, echo=True,
                       line=LineSettings(baud=19200), interface="tty")
    got = [(r.systat, r.field) for r in refusals(settings)]
    assert got == [
        (0x8B, "line.baud"), (0x8B, "line.baud"),              # over TTY's 9600, over the total
        (0x8D, "echo"), (0x8D, "xon_xoff_output"),
        (0x8E, "zvz_ms"), (0x8F, "receive_db"), (0x90, "cpu"), (0x91, "identifier"),
        (0x95, "xoff_ms"),
    ]


# ---- what cannot be written into the block at all --------------------------------------

@pytest.mark.parametrize("options", [
    {"receive_db": 256}, {"receive_dw": 256}, {"receive_dw": -1}, {"cpu": -1},
    {"identifier": 256}, {"zvz_ms": 65536}, {"zvz_ms": -1}, {"xoff_ms": 65536},
    {"telegram_length": 65536}, {"end_chars": (0x100, 0)}, {"end_chars": (1,)},
    {"end_criterion": "stx"}, {"interface": "rs485"},
])
def test_not_writable(options):
    with pytest.raises(ValueError):
        replace(DB189, **options)


@pytest.mark.parametrize("words", [(0,) * 7, (0,) * 9, (0,) * 7 + (0x10000,), (-1,) + (0,) * 7])
def test_format_rejects_a_block_that_is_not_eight_words(words):
    with pytest.raises(ValueError):
        format_data_block(words)


def test_refusal_str():
    assert str(Refusal(0x90, "cpu", "CPU number 5 is greater than 4")) == (
        "SYSTAT 90h: CPU number 5 is greater than 4")


def test_pure_without_serial_or_socket():
    code = ("import sys; sys.modules['serial'] = None; sys.modules['socket'] = None; "
            "import prc3cfg.core.gateway")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).parents[1])
