"""read_log splits MCAP chunks itself (the rebuild's hot path): the same records, in the same order, as mcap's."""

from pathlib import Path

import pytest
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from pairplay.replay.reader import ChunkOverrun, _chunk_records, read_log

SAMPLES = sorted((Path(__file__).resolve().parents[1] / "recordings" / "samples").glob("*.mcap"))


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.name)
def test_chunks_split_into_mcaps_own_records(path):
    with open(path, "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    assert chunks
    for chunk in chunks:
        ours = list(_chunk_records(chunk))
        theirs = [(r.channel_id, r.log_time, r.data) if isinstance(r, Message) else r for r in breakup_chunk(chunk)]
        assert ours == theirs


def test_a_record_overrunning_its_chunk_ends_the_read_as_a_corrupt_tail(tmp_path):
    path = SAMPLES[0]
    with open(path, "rb") as f:
        chunk = next(r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk))
    cut = Chunk(compression="", data=b"\x05" + (1 << 40).to_bytes(8, "little"), message_end_time=0,
                message_start_time=0, uncompressed_crc=0, uncompressed_size=9)
    with pytest.raises(ChunkOverrun):
        list(_chunk_records(cut))
    whole = read_log(path)
    assert not whole.truncated and whole.events and not whole.bad
