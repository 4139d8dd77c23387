"""A recording with a compression "bomb" chunk is refused as damaged without allocating what it decompresses to.

Rule (replay/mcapscan.py `_decompress`): a chunk is decompressed to at most its declared uncompressed size, and
a declared size above MAX_CHUNK (64 MiB; pairplay writes chunks of 256 KiB plus one message) is refused before
anything is allocated. The trial (trial28 F15): a 191 KB file whose chunk held 98 KB of zstd that decompress to
3 GiB made `rebuild`, `replay --verify`, `recover` and `view` each reach 3.25 GB of RSS before saying "decompresses
to 3221225472 bytes, the chunk says 4671": zstandard sizes its output by the frame's content size, whatever
`max_output_size` says. Every verb reads a recording through mcapscan.scan, so each is a real `python -m pairplay`
here; its peak RSS is the child's own (os.wait4's rusage), with a generous bound: the bombs decompress to 1 GiB.
A child's peak is never below its parent's at the spawn (exec keeps the high-water mark of the vfork'ed memory), so
the bound is this process's peak plus 300 MB (a verb reading the whole file adds ~110 MB; before, 1.1 GB).
"""

from __future__ import annotations

import io
import os
import resource
import struct
import subprocess
import sys

import lz4.frame
import pytest
import zstandard

from pairplay.replay.mcapscan import MAX_CHUNK, scan

from damageutil import small_chunked_session

BOMB = 1 << 30  # bytes the bomb decompresses to
GROWTH_KB = 300 * 1024  # a verb's peak RSS above ours: far below the bomb


def _zstd_bomb() -> bytes:
    """One zstd frame of BOMB zero bytes whose header says so (33 KB)."""
    out = io.BytesIO()
    with zstandard.ZstdCompressor(level=1).stream_writer(out, size=BOMB, closefd=False) as w:
        zeros = bytes(1 << 20)
        for _ in range(BOMB >> 20):
            w.write(zeros)
    return out.getvalue()


def _lz4_bomb() -> bytes:
    """An lz4 frame of BOMB // 4 zero bytes (1.1 MB): lz4 compresses no better than 1:255."""
    c = lz4.frame.LZ4FrameCompressor()
    zeros = bytes(1 << 20)
    return b"".join([c.begin(source_size=BOMB // 4), *(c.compress(zeros) for _ in range(BOMB // 4 >> 20)), c.flush()])


def _bombed(whole, path, compression: str, data: bytes, declared: int):
    """`whole` with its middle chunk replaced by a Chunk record of `data` declaring `declared` bytes (no CRC)."""
    chunks = scan(whole).chunks
    c = chunks[len(chunks) // 2]
    raw = whole.read_bytes()
    name = compression.encode()
    content = (struct.pack("<QQQII", c.start, c.end, declared, 0, len(name)) + name
               + struct.pack("<Q", len(data)) + data)
    path.write_bytes(raw[:c.offset] + struct.pack("<BQ", 0x06, len(content)) + content + raw[c.offset + c.length:])
    return path


@pytest.fixture(scope="module")
def bombs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bomb")
    whole = small_chunked_session(folder / "whole.mcap", "bomb")
    z = _zstd_bomb()
    return {"zstd, declared small": _bombed(whole, folder / "zlie.mcap", "zstd", z, 4671),
            "zstd, declared huge": _bombed(whole, folder / "ztrue.mcap", "zstd", z, BOMB),
            "lz4, declared small": _bombed(whole, folder / "l4lie.mcap", "lz4", _lz4_bomb(), 4671)}


def _run(args, cwd) -> tuple[int, str, int]:
    """(exit code, stderr, peak RSS in KB above ours) of `python -m pairplay ARGS`, its RSS its own (wait4's
    rusage)."""
    ours = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, err, usage.ru_maxrss - ours


@pytest.mark.parametrize("kind", ["zstd, declared small", "zstd, declared huge", "lz4, declared small"])
def test_verify_refuses_a_bomb_chunk_in_bounded_memory(bombs, kind, tmp_path):
    code, err, peak = _run(["replay", "--verify", str(bombs[kind])], tmp_path)
    assert code == 1 and "Traceback" not in err, err
    assert peak < GROWTH_KB, f"{kind}: peak RSS {peak} KB"


@pytest.mark.parametrize("verb", ["rebuild", "recover", "view"])
def test_rebuild_recover_and_view_refuse_a_bomb_chunk_in_one_line_in_bounded_memory(bombs, verb, tmp_path):
    path = bombs["zstd, declared small"]
    args = {"rebuild": ["rebuild", str(path), "--out", str(tmp_path / "out")],
            "recover": ["recover", str(path), "-o", str(tmp_path / "rec.mcap")],
            "view": ["view", "--recording", str(path), "--out", str(tmp_path / "v.rrd")]}[verb]
    code, err, peak = _run(args, tmp_path)
    assert "Traceback" not in err, err
    assert peak < GROWTH_KB, f"{verb}: peak RSS {peak} KB"
    if verb == "rebuild":  # a lost part: refused without --partial, in one line naming the chunk
        assert code == 2 and len(err.strip().splitlines()) == 1 and "decompresses to 1073741824 bytes" in err, err
    if verb == "view":  # its intact parts are shown, the damage said
        assert "decompresses to 1073741824 bytes" in err, err


def test_the_scan_says_what_the_bomb_chunk_is(bombs):
    said = {kind: scan(path).describe() for kind, path in bombs.items()}
    assert "decompresses to 1073741824 bytes (its zstd frame says), the chunk says 4671" in said["zstd, declared small"]
    assert f"declares 1073741824 bytes uncompressed, more than any chunk a recorder writes " \
           f"({MAX_CHUNK} bytes): not read" in said["zstd, declared huge"]
    assert "decompresses to more than 4671 bytes, the chunk says 4671" in said["lz4, declared small"]
