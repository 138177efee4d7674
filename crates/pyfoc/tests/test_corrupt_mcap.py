"""pyfoc.tune_qr_mcap and pyfoc.read_log on an MCAP log whose record length field is corrupt
(2^64 - 1, 2^63, 2^32): pyfoc.PyfocError naming the file, never pyo3's PanicException."""
import struct

import pytest

import pyfoc


@pytest.fixture(scope="module")
def log_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("corrupt") / "run.mcap"
    assert pyfoc.simulate("default", duration=0.01, mcap=path)["completed"]
    return path.read_bytes()


def third_record(b):
    """Offset of the third record (after the header and the first chunk)."""
    at = 8
    for _ in range(2):
        at += 9 + struct.unpack_from("<Q", b, at + 1)[0]
    return at


@pytest.mark.parametrize("length", [2**64 - 1, 2**63, 2**32])
def test_corrupt_record_length(tmp_path, log_bytes, length):
    b = bytearray(log_bytes)
    struct.pack_into("<Q", b, third_record(b) + 1, length)
    p = tmp_path / "corrupt.mcap"
    p.write_bytes(bytes(b))
    with pytest.raises(pyfoc.PyfocError, match="corrupt.mcap") as e:
        pyfoc.tune_qr_mcap(p)
    assert "corrupt MCAP file" in str(e.value)
    with pytest.raises(pyfoc.PyfocError, match="corrupt.mcap"):
        pyfoc.read_log(p)
