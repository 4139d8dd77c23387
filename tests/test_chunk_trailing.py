"""A chunk's compressed data is read to its end: bytes after its first frame are a finding, never dropped.

Rule (replay/mcapscan.py `_decompress`): every zstd or lz4 frame of a chunk's data is decompressed, in turn, and
what they make together is checked against the chunk's uncompressed size and CRC (the MCAP spec); bytes after
the last whole frame are damage. Before, zstandard's and lz4's decoders stopped at the end of the first frame:
a chunk whose first frame held its declared bytes (size and CRC held) and a second frame or junk after it was
read as whole, the rest dropped without a word. Every verb reads a recording through mcapscan.scan; `replay
--verify` is a real `python -m pairplay` here. Real parts: a real recording written in small chunks, one chunk's
Chunk record rewritten.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import zlib

import lz4.frame
import pytest
import zstandard

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_any_log

from damageutil import small_chunked_session


def _rewritten(whole, path, compression: str, data: bytes, declared: int, crc: int):
    """`whole` with its middle chunk's record holding `data` compressed by `compression`, declaring `declared`
    uncompressed bytes and `crc`."""
    chunks = scan(whole).chunks
    c = chunks[len(chunks) // 2]
    raw = whole.read_bytes()
    name = compression.encode()
    content = (struct.pack("<QQQII", c.start, c.end, declared, crc, len(name)) + name
               + struct.pack("<Q", len(data)) + data)
    path.write_bytes(raw[:c.offset] + struct.pack("<BQ", 0x06, len(content)) + content + raw[c.offset + c.length:])
    return path


def _records_of_middle_chunk(whole) -> bytes:
    """The uncompressed records of `whole`'s middle chunk, as its writer compressed them."""
    chunks = scan(whole).chunks
    c = chunks[len(chunks) // 2]
    raw = whole.read_bytes()
    opcode, length = struct.unpack_from("<BQ", raw, c.offset)
    content = raw[c.offset + 9:c.offset + 9 + length]
    _, _, size, crc, n = struct.unpack_from("<QQQII", content)
    name = content[32:32 + n].decode()
    (m,) = struct.unpack_from("<Q", content, 32 + n)
    data = content[40 + n:40 + n + m]
    assert name == "zstd" and len(data) == m
    records = zstandard.ZstdDecompressor().decompress(data)
    assert len(records) == size and zlib.crc32(records) == crc
    return records


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trailing")
    whole = small_chunked_session(folder / "whole.mcap", "trailing")
    records = _records_of_middle_chunk(whole)
    size, crc = len(records), zlib.crc32(records)
    z, lz = zstandard.ZstdCompressor().compress, lz4.frame.compress
    half = len(records) // 2
    return {
        "whole": whole,
        # the chunk's records in one frame, then a second frame (a hidden message's worth) or junk
        "zstd, a second frame": _rewritten(whole, folder / "z2.mcap", "zstd", z(records) + z(b"\x05" * 40), size, crc),
        "zstd, junk after": _rewritten(whole, folder / "zj.mcap", "zstd", z(records) + b"junk", size, crc),
        "lz4, a second frame": _rewritten(whole, folder / "l2.mcap", "lz4", lz(records) + lz(b"\x05" * 40), size, crc),
        "lz4, junk after": _rewritten(whole, folder / "lj.mcap", "lz4", lz(records) + b"junkjunk", size, crc),
        # the records in two frames, as zstd and lz4 allow: read whole
        "zstd, split in two": _rewritten(whole, folder / "zs.mcap", "zstd", z(records[:half]) + z(records[half:]),
                                         size, crc),
        "lz4, split in two": _rewritten(whole, folder / "ls.mcap", "lz4", lz(records[:half]) + lz(records[half:]),
                                        size, crc),
    }


TRAILING = ["zstd, a second frame", "zstd, junk after", "lz4, a second frame", "lz4, junk after"]


@pytest.mark.parametrize("kind", TRAILING)
def test_bytes_after_a_chunks_first_frame_are_a_finding_of_that_chunk(files, kind):
    checked = scan(files[kind])
    assert not checked.whole, kind
    [lost] = checked.lost_chunks
    said = checked.describe()
    assert said.startswith(f"chunk {lost.number} "), said
    # junk: said as such; a second frame: what the frames make together is more than the chunk says
    assert ("after its last frame" if "junk" in kind else "decompresses to ") in said, said
    log = read_any_log(files[kind])  # the reader every verb reads through: the damage said
    assert log.damage and log.damaged, kind
    assert len(log.events) < len(read_any_log(files["whole"]).events)


@pytest.mark.parametrize("kind", ["zstd, split in two", "lz4, split in two"])
def test_a_chunk_compressed_in_several_frames_is_read_whole(files, kind):
    checked = scan(files[kind])  # (the rewritten chunk's new length breaks the data section's CRC and the summary)
    assert not checked.lost_chunks, checked.describe()
    assert [r.payload for r in read_any_log(files[kind]).events] == [r.payload for r in
                                                                     read_any_log(files["whole"]).events]


def test_verify_fails_a_recording_whose_chunk_has_a_second_frame(files, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pairplay", "replay", "--verify", str(files["zstd, a second frame"])],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "(its 2 zstd frames say), the chunk says" in proc.stdout, (proc.stdout, proc.stderr)
