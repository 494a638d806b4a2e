"""Copy a bag without its /sim/... topics (what an operator's recorder would hold): schemas, channels,
messages, metadata and attachments of every other topic are copied byte for byte."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import Writer


def strip_sim(src: Path, dst: Path) -> int:
    """Write ``dst`` = ``src`` minus /sim topics; returns the number of /sim messages dropped."""
    dropped = 0
    dst.parent.mkdir(parents=True, exist_ok=True)
    with open(src, "rb") as fi, open(dst, "wb") as fo:
        r = make_reader(fi)
        head = r.get_header()
        w = Writer(fo)
        w.start(profile=head.profile, library=head.library)
        schemas, chans = {}, {}
        for schema, ch, msg in r.iter_messages():
            if ch.topic.startswith("/sim"):
                dropped += 1
                continue
            if ch.id not in chans:
                sid = 0
                if schema is not None:
                    if schema.id not in schemas:
                        schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                    sid = schemas[schema.id]
                chans[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid, dict(ch.metadata))
            w.add_message(chans[ch.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        for m in r.iter_metadata():
            w.add_metadata(m.name, dict(m.metadata))
        for a in r.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        w.finish()
    return dropped


def strip_fleet(src_dir: Path, dst_dir: Path) -> int:
    n = 0
    for p in sorted(Path(src_dir).glob("*/*.mcap")):
        n += strip_sim(p, Path(dst_dir) / p.parent.name / p.name)
    return n
