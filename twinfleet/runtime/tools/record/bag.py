"""`twinfleet bag info`: what a recording holds, as `ros2 bag info` tells it; and the one check
every reader of a recording makes first.

`read_summary(path)` opens an MCAP file and returns its summary (duration,
message counts per channel, schemas), rebuilding it by a scan when the file
has no summary section (a recording cut short). A file that is not MCAP, or
whose records are corrupt or truncated, raises `RecordingError` with one line
naming the file and the problem, so `play`, `export` and `bag info` never
show a traceback for a bad file.
"""

from __future__ import annotations

import struct
import zlib
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

from mcap.exceptions import McapError
from mcap.reader import make_reader

READ_ERRORS = (McapError, struct.error, zlib.error, ValueError, EOFError, KeyError)


class RecordingError(ValueError):
    """A recording cannot be read; the text names the file and what is wrong."""


@dataclass
class Summary:
    """What `bag info` prints: per channel its topic, type, encoding and message count."""

    path: Path
    size: int
    start_ns: int = 0
    end_ns: int = 0
    channels: list[dict[str, Any]] = field(default_factory=list)
    schemas: dict[str, str] = field(default_factory=dict)  # schema name → encoding
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    indexed: bool = True

    @property
    def messages(self) -> int:
        """Messages in the file."""
        return sum(c["count"] for c in self.channels)


def _fail(path: Path, exc: BaseException) -> RecordingError:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return RecordingError(f"{path}: not a readable MCAP recording, corrupt or truncated ({text}); "
                          f"if its recorder was killed or the disk filled up, `twinfleet bag "
                          f"repair {path}` recovers every complete chunk")


def repair(path: str | Path, output: str | Path | None = None) -> tuple[int, Path]:
    """Rewrite the readable prefix of a recording cut short as a complete MCAP file.

    Reads records in file order until the first incomplete one (a chunk half
    written when the recorder died), then writes the schemas, channels,
    metadata and messages read so far, with a summary, to `output` (default:
    `path`, replaced atomically). Returns (messages written, output path).

    Raises:
        RecordingError: not an MCAP file at all (no header), or nothing readable.
        OSError: the output cannot be written.
    """
    from mcap.reader import NonSeekingReader
    from mcap.writer import Writer

    path = Path(path)
    target = Path(output) if output is not None else path
    records = _readable_prefix(path, NonSeekingReader)
    tmp = target.with_name(f".{target.name}.repair")
    with tmp.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="twinfleet bag repair")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in records:
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding,
                    schemas.get(schema.id, 0) if schema is not None else 0, dict(channel.metadata))
            writer.add_message(channels[channel.id], log_time=message.log_time,
                               data=message.data, publish_time=message.publish_time,
                               sequence=message.sequence)
        writer.finish()
    tmp.replace(target)
    return len(records), target


def _readable_prefix(path: Path, reader_class: Any) -> list[tuple[Any, Any, Any]]:
    """(schema, channel, message) of every message before the first unreadable record."""
    found: list[tuple[Any, Any, Any]] = []
    with path.open("rb") as stream:
        try:
            for item in reader_class(stream).iter_messages(log_time_order=False):
                found.append(item)
        except READ_ERRORS:  # EndOfFile or a torn record: the cut, everything before it is kept
            pass
    if not found and not _has_magic(path):
        raise RecordingError(f"{path}: not an MCAP recording (no MCAP header)")
    return found


def _has_magic(path: Path) -> bool:
    with path.open("rb") as stream:
        return stream.read(8) == b"\x89MCAP0\r\n"


def read_summary(path: str | Path) -> Summary:
    """The summary of an MCAP file (scanned when the file has none).

    Raises:
        RecordingError: not MCAP, corrupt or truncated.
        OSError: the file cannot be opened.
    """
    path = Path(path)
    with path.open("rb") as stream:
        try:
            reader = make_reader(stream)
            summary = reader.get_summary()
            if summary is not None and summary.statistics is not None:
                out = _from_summary(path, summary)
            else:
                out = _scan(path, reader)
            out.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except READ_ERRORS as exc:
            raise _fail(path, exc) from None
    return out


def _from_summary(path: Path, summary: Any) -> Summary:
    stats = summary.statistics
    out = Summary(path, path.stat().st_size, stats.message_start_time, stats.message_end_time)
    for cid, channel in sorted(summary.channels.items()):
        schema = summary.schemas.get(channel.schema_id)
        out.channels.append({"topic": channel.topic, "type": schema.name if schema else "",
                             "encoding": channel.message_encoding,
                             "count": stats.channel_message_counts.get(cid, 0)})
    out.schemas = {s.name: s.encoding for s in summary.schemas.values()}
    return out


def _scan(path: Path, reader: Any) -> Summary:
    out = Summary(path, path.stat().st_size, indexed=False)
    counts: Counter[int] = Counter()
    channels: dict[int, dict[str, Any]] = {}
    first = last = None
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        counts[channel.id] += 1
        channels.setdefault(channel.id, {"topic": channel.topic,
                                         "type": schema.name if schema else "",
                                         "encoding": channel.message_encoding})
        if schema is not None:
            out.schemas[schema.name] = schema.encoding
        first = message.log_time if first is None else min(first, message.log_time)
        last = message.log_time if last is None else max(last, message.log_time)
    out.start_ns, out.end_ns = first or 0, last or 0
    out.channels = [{**channels[c], "count": counts[c]} for c in sorted(channels)]
    return out


def check_readable(path: str | Path) -> None:
    """Read every record of a recording once (`play` does it before publishing anything)."""
    path = Path(path)
    with path.open("rb") as stream:
        try:
            for _ in make_reader(stream).iter_messages(log_time_order=False):
                pass
        except READ_ERRORS as exc:
            raise _fail(path, exc) from None


def _stamp(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def print_info(s: Summary, out: TextIO) -> None:
    """`ros2 bag info`-style text."""
    duration = max(0, s.end_ns - s.start_ns) / 1e9
    width = max((len(c["topic"]) for c in s.channels), default=0)
    fleet = s.metadata.get("twinfleet", {}).get("fleet")
    lines = [f"Files:             {s.path}",
             f"Bag size:          {s.size / 1024:.1f} KiB",
             "Storage id:        mcap" + ("" if s.indexed else " (no summary: scanned)"),
             f"Duration:          {duration:.3f} s",
             f"Start:             {_stamp(s.start_ns) if s.channels else '-'}",
             f"End:               {_stamp(s.end_ns) if s.channels else '-'}",
             f"Messages:          {s.messages}"]
    if fleet:
        lines.append(f"Fleet:             {fleet}")
    lines.append(f"Topic information: {len(s.channels)} channels")
    for c in sorted(s.channels, key=lambda c: (c["topic"], c["type"])):
        lines.append(f"  {c['topic']:<{width}}  type: {c['type']:<30}  count: {c['count']:>6}  "
                     f"encoding: {c['encoding']}")
    lines.append(f"Schemas:           {len(s.schemas)}")
    lines += [f"  {name} ({encoding})" for name, encoding in sorted(s.schemas.items())]
    out.write("\n".join(lines) + "\n")
    out.flush()
