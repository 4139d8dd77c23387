"""Completing a recording cut short by a crash (`pairplay recover`).

Rule: every complete record before the cut is copied, in order, into a new
file that is then finished with a summary and index, so any MCAP reader opens
it. Nothing is invented: the lost tail stays lost, and a "pairplay.recovered"
metadata record says what was read, from where, and why the original stopped.
A complete file recovers to an equivalent complete file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from pairplay.errors import OutputError
from pairplay.outputs import check_output, output_file

from .check import check_recording
from .reader import iter_records
from .writer import CHUNK_SIZE, PROFILE


@dataclass
class Recovered:
    output: Path
    messages: int
    truncated: bool
    reason: str


def default_output(path: Path) -> Path:
    return path.with_name(path.stem + ".recovered.mcap")


def recover(path: str | Path, output: str | Path | None = None, force: bool = False) -> Recovered:
    """Copy the readable records of `path` into a complete file (see rule).

    InputError if `path` is not an MCAP file at all; OutputError if `output` exists
    (unless `force`) or is the input; the output appears only when complete
    (pairplay.outputs)."""
    path = check_recording(path)
    output = Path(output) if output is not None else default_output(path)
    if output.resolve() == path.resolve():
        raise OutputError("recover writes a new file; give an output path other than the input", output)
    check_output(output, force)
    messages, truncated, reason = 0, False, ""
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    with output_file(output, "wb", force) as out:
        writer = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        writer.start(profile=PROFILE, library="pairplay recover")
        try:
            for record in iter_records(path):
                if isinstance(record, Schema):
                    if record.id not in schema_ids:
                        schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel):
                    if record.id not in channel_ids:
                        channel_ids[record.id] = writer.register_channel(
                            record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0),
                            dict(record.metadata))
                elif isinstance(record, Message):
                    if record.channel_id in channel_ids:
                        writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                           record.publish_time, record.sequence)
                        messages += 1
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                elif isinstance(record, Footer):
                    break
        except Exception as err:  # the cut: everything before it is kept
            truncated, reason = True, f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
        writer.add_metadata("pairplay.recovered", {
            "source": str(path), "messages": str(messages), "truncated": str(truncated).lower(), "reason": reason})
        writer.finish()
    return Recovered(output, messages, truncated, reason)
