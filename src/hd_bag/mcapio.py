"""Minimal, fast MCAP record layer (spec: https://mcap.dev/spec), numpy based.

Why our own and not ``mcap.writer``/``mcap.reader``: the contract topics carry
fixed-layout messages at 1 to 20 kHz, and the per-message Python cost of the
generic libraries (record objects, one call per message) dominates reading and
writing. Here whole blocks of same-length Message records are built and cut
with numpy, and the reader streams one chunk at a time, so memory is bounded by
the chunk size, not the file size. Everything written here is read back by
``mcap``, ``mcap-ros2-support`` and ``rosbags`` (tested).

The reader is tolerant by design: a file that ends early (a recorder killed
mid-run) yields every complete chunk before the cut and reports the truncation
through :class:`ScanIssue` objects instead of raising; corrupt bytes (bad CRC,
undecodable chunk, impossible record length) raise :class:`McapFormatError`.
"""

from __future__ import annotations

import io
import os
import struct
import threading
import zlib
from dataclasses import dataclass, field
from typing import BinaryIO, Iterator

import numpy as np

MAGIC = b"\x89MCAP0\r\n"

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_ATTACHMENT = 0x09
OP_ATTACHMENT_INDEX = 0x0A
OP_STATISTICS = 0x0B
OP_METADATA = 0x0C
OP_METADATA_INDEX = 0x0D
OP_SUMMARY_OFFSET = 0x0E
OP_DATA_END = 0x0F

#: Message record fixed part: channel_id u16, sequence u32, log_time u64, publish_time u64.
MSG_FIXED = 2 + 4 + 8 + 8
#: Caps on every size read from a file (see docs/ROBUSTNESS.md "Caps"). They follow from the
#: contract: the largest chunk a known writer produces is a few MiB (ours: 0.5 MiB or 1 s of log
#: time, i.e. ~3 MiB at 20 kHz; the recorder: 20,000 messages; ``ros2 bag``: 768 KiB; ``mcap``:
#: 1 MiB), so a chunk that decompresses to more than 64 MiB (20x the largest of them) is not a
#: contract bag, it is a decompression bomb or corrupt length bytes.
MAX_CHUNK_BYTES = 64 << 20
#: Schema / Channel / Metadata / Header records: texts of a few KiB (JointState's schema with its
#: dependencies: 0.5 KiB); 4 MiB leaves room for any real message definition.
MAX_META_RECORD = 4 << 20
#: One Message record outside a chunk (unchunked bags): contract messages are < 1 KiB.
MAX_LOOSE_MESSAGE = 4 << 20
#: Upper bound on a record's length field in the data section (a chunk record carries at most
#: MAX_CHUNK_BYTES of compressed data plus its header): larger means corrupt length bytes.
MAX_RECORD = MAX_CHUNK_BYTES + 4096
#: opcodes the spec defines (0x80-0xFF are user records, skipped)
VALID_OPS = frozenset(range(0x01, 0x10))


class McapFormatError(ValueError):
    """The bytes are not a valid MCAP stream (message names what and where)."""


# ---------------------------------------------------------------------------
# primitive encoders
# ---------------------------------------------------------------------------
def _s(x: str) -> bytes:
    b = x.encode("utf-8")
    return struct.pack("<I", len(b)) + b


def _map_ss(d: dict[str, str]) -> bytes:
    body = b"".join(_s(k) + _s(v) for k, v in d.items())
    return struct.pack("<I", len(body)) + body


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def header_record(profile: str, library: str) -> bytes:
    return _record(OP_HEADER, _s(profile) + _s(library))


def schema_record(sid: int, name: str, encoding: str, data: bytes) -> bytes:
    return _record(OP_SCHEMA, struct.pack("<H", sid) + _s(name) + _s(encoding) + struct.pack("<I", len(data)) + data)


def channel_record(cid: int, sid: int, topic: str, msg_enc: str, metadata: dict[str, str]) -> bytes:
    return _record(OP_CHANNEL, struct.pack("<HH", cid, sid) + _s(topic) + _s(msg_enc) + _map_ss(metadata))


def metadata_record(name: str, metadata: dict[str, str]) -> bytes:
    return _record(OP_METADATA, _s(name) + _map_ss(metadata))


def message_records(channel_id: int, seq: np.ndarray, log_time: np.ndarray, publish_time: np.ndarray,
                    payload: np.ndarray) -> np.ndarray:
    """Message records for ``n`` same-length payloads, as an (n, 9 + 22 + L) uint8 array.

    ``payload`` is an (n, L) uint8 array of serialised messages.
    """
    n, L = payload.shape
    rec = np.empty((n, 9 + MSG_FIXED + L), dtype=np.uint8)
    rec[:, 0] = OP_MESSAGE
    rec[:, 1:9] = np.frombuffer(struct.pack("<Q", MSG_FIXED + L), np.uint8)
    rec[:, 9:11] = np.frombuffer(struct.pack("<H", channel_id), np.uint8)
    rec[:, 11:15] = np.ascontiguousarray(seq, dtype="<u4").view(np.uint8).reshape(n, 4)
    rec[:, 15:23] = np.ascontiguousarray(log_time, dtype="<u8").view(np.uint8).reshape(n, 8)
    rec[:, 23:31] = np.ascontiguousarray(publish_time, dtype="<u8").view(np.uint8).reshape(n, 8)
    rec[:, 31:] = payload
    return rec


def _compress(data: bytes, compression: str) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        return _zstd_compressor().compress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.compress(data)
    raise ValueError(f"unsupported chunk compression {compression!r} (zstd, lz4 or none)")


#: one zstd (de)compressor per thread: zstandard's objects are not thread-safe (two threads sharing one,
#: e.g. a multi-threaded Dask worker reading two bags, get "Data corruption detected")
_Z = threading.local()


def _zstd_compressor():
    zc = getattr(_Z, "c", None)
    if zc is None:
        import zstandard

        zc = _Z.c = zstandard.ZstdCompressor(level=3)
    return zc


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    """Decompress a chunk, never producing more than ``size + 1`` bytes (``size``: the chunk's declared
    uncompressed size, already checked against :data:`MAX_CHUNK_BYTES`): a frame that claims or expands
    to more is cut there and the caller refuses the size mismatch, so a bomb costs at most the cap."""
    if compression == "":
        return data
    if compression == "zstd":
        zd = getattr(_Z, "d", None)
        if zd is None:
            import zstandard

            zd = _Z.d = zstandard.ZstdDecompressor()
        with zd.stream_reader(io.BytesIO(data)) as r:
            return _read_capped(r, size + 1)
    if compression == "lz4":
        import lz4.frame

        with lz4.frame.open(io.BytesIO(data), "rb") as r:
            return _read_capped(r, size + 1)
    raise McapFormatError(f"unsupported chunk compression {compression!r}")


def _read_capped(r, n: int) -> bytes:
    parts, got = [], 0
    while got < n:
        b = r.read(min(n - got, 1 << 22))
        if not b:
            break
        parts.append(b)
        got += len(b)
    return b"".join(parts)


# ---------------------------------------------------------------------------
# writer
# ---------------------------------------------------------------------------
@dataclass
class _ChunkInfo:
    start: int
    end: int
    offset: int
    length: int
    mi_offsets: dict[int, int]
    mi_length: int
    compressed_size: int
    uncompressed_size: int


class McapFileWriter:
    """Append-only MCAP writer: schemas/channels/metadata up front, then chunks.

    Each :meth:`write_chunk` writes one complete Chunk record and its Message
    Index records, then flushes the file, so a process killed at any moment
    leaves every earlier chunk readable. :meth:`close` adds the summary section
    (schemas, channels, statistics, chunk and metadata indexes) and the footer.
    """

    def __init__(self, path: str | os.PathLike, *, profile: str = "ros2", library: str = "hdphm hd_bag",
                 compression: str = "zstd", fsync: bool = False):
        if compression in (None, "none"):
            compression = ""
        if compression not in ("", "zstd", "lz4"):
            raise ValueError(f"unsupported chunk compression {compression!r} (zstd, lz4 or none)")
        self.path = os.fspath(path)
        self.compression = compression
        self.fsync = fsync
        self._f: BinaryIO = open(self.path, "wb")
        self._pos = 0
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._meta_index: list[bytes] = []
        self._chunks: list[_ChunkInfo] = []
        self._counts: dict[int, int] = {}
        self._t0: int | None = None
        self._t1: int | None = None
        self._closed = False
        self._write(MAGIC + header_record(profile, library))

    def _write(self, b: bytes) -> None:
        self._f.write(b)
        self._pos += len(b)

    def add_schema(self, sid: int, name: str, encoding: str, data: bytes) -> None:
        rec = schema_record(sid, name, encoding, data)
        self._schemas.append(rec)
        self._write(rec)

    def add_channel(self, cid: int, sid: int, topic: str, msg_enc: str, metadata: dict[str, str]) -> None:
        rec = channel_record(cid, sid, topic, msg_enc, metadata)
        self._channels.append(rec)
        self._write(rec)

    def add_metadata(self, name: str, metadata: dict[str, str]) -> None:
        rec = metadata_record(name, metadata)
        off = self._pos
        self._write(rec)
        self._meta_index.append(_record(OP_METADATA_INDEX, struct.pack("<QQ", off, len(rec)) + _s(name)))
        self.flush()

    def write_chunk(self, blocks: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Write one chunk from ``(channel_id, log_time[n], records)`` blocks.

        ``records`` are complete Message records: an (n, W) uint8 array (see
        :func:`message_records`) or a list of n ``bytes`` of any length.
        Blocks are stored in the given order.
        """
        blocks = [b for b in blocks if len(b[1])]
        if not blocks:
            return
        parts = []
        mi: dict[int, list[np.ndarray]] = {}
        off = 0
        t0 = min(int(b[1].min()) for b in blocks)
        t1 = max(int(b[1].max()) for b in blocks)
        for cid, lt, rec in blocks:
            if isinstance(rec, np.ndarray):
                n, w = rec.shape
                offs = off + w * np.arange(n, dtype=np.uint64)
                parts.append(rec.tobytes())
                size = n * w
            else:  # list of record bytes of varying length
                n = len(rec)
                ln = np.array([len(r) for r in rec], np.uint64)
                offs = off + np.concatenate([[0], np.cumsum(ln)[:-1]]).astype(np.uint64)
                parts.append(b"".join(rec))
                size = int(ln.sum())
            mi.setdefault(cid, []).append(np.stack([np.asarray(lt, np.uint64), offs], axis=1))
            off += size
            self._counts[cid] = self._counts.get(cid, 0) + n
        raw = b"".join(parts)
        crc = zlib.crc32(raw)
        comp = _compress(raw, self.compression)
        content = (struct.pack("<QQQI", t0, t1, len(raw), crc) + _s(self.compression)
                   + struct.pack("<Q", len(comp)) + comp)
        chunk = _record(OP_CHUNK, content)
        chunk_off = self._pos
        self._write(chunk)
        mi_start = self._pos
        mi_offsets = {}
        for cid, arrs in mi.items():
            a = np.concatenate(arrs)
            a = a[np.argsort(a[:, 0], kind="stable")]
            body = a.astype("<u8").tobytes()
            mi_offsets[cid] = self._pos
            self._write(_record(OP_MESSAGE_INDEX, struct.pack("<HI", cid, len(body)) + body))
        self._chunks.append(_ChunkInfo(t0, t1, chunk_off, len(chunk), mi_offsets, self._pos - mi_start,
                                       len(comp), len(raw)))
        self._t0 = t0 if self._t0 is None else min(self._t0, t0)
        self._t1 = t1 if self._t1 is None else max(self._t1, t1)
        self.flush()

    def flush(self) -> None:
        self._f.flush()
        if self.fsync:
            os.fsync(self._f.fileno())

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._write(_record(OP_DATA_END, struct.pack("<I", 0)))
        summary_start = self._pos
        groups: list[tuple[int, int, int]] = []

        def group(op: int, recs: list[bytes]) -> None:
            if recs:
                start = self._pos
                for r in recs:
                    self._write(r)
                groups.append((op, start, self._pos - start))

        group(OP_SCHEMA, self._schemas)
        group(OP_CHANNEL, self._channels)
        cm = b"".join(struct.pack("<HQ", c, n) for c, n in sorted(self._counts.items()))
        stats = (struct.pack("<QHIIII", sum(self._counts.values()), len(self._schemas), len(self._channels), 0,
                             len(self._meta_index), len(self._chunks))
                 + struct.pack("<QQ", self._t0 or 0, self._t1 or 0) + struct.pack("<I", len(cm)) + cm)
        group(OP_STATISTICS, [_record(OP_STATISTICS, stats)])
        cis = []
        for c in self._chunks:
            mio = b"".join(struct.pack("<HQ", k, v) for k, v in c.mi_offsets.items())
            cis.append(_record(OP_CHUNK_INDEX, struct.pack("<QQQQ", c.start, c.end, c.offset, c.length)
                               + struct.pack("<I", len(mio)) + mio + struct.pack("<Q", c.mi_length)
                               + _s(self.compression) + struct.pack("<QQ", c.compressed_size, c.uncompressed_size)))
        group(OP_CHUNK_INDEX, cis)
        group(OP_METADATA_INDEX, self._meta_index)
        so_start = self._pos
        for op, start, length in groups:
            self._write(_record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, start, length)))
        # Footer: summary_crc 0 = not computed (allowed by the spec).
        self._write(_record(OP_FOOTER, struct.pack("<QQI", summary_start, so_start, 0)) + MAGIC)
        self._f.flush()
        self._f.close()

    def abort(self) -> None:
        """Close the file without a summary (as if the process had died)."""
        if not self._closed:
            self._closed = True
            self._f.close()


# ---------------------------------------------------------------------------
# reader
# ---------------------------------------------------------------------------
@dataclass
class SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class ChannelRec:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass
class MessageBlock:
    """The messages of one chunk (or loose messages), as numpy arrays.

    ``buf`` is the chunk's decompressed record bytes; message ``i`` has its
    payload at ``buf[start[i] : start[i] + length[i]]``.
    """

    buf: np.ndarray  # uint8
    channel: np.ndarray  # uint16
    log_time: np.ndarray  # uint64
    start: np.ndarray  # int64
    length: np.ndarray  # int64
    loose: bool = False  # messages found outside chunks (``buf`` holds payloads only, no records)


@dataclass
class ScanIssue:
    """A problem met while scanning the file (position in bytes)."""

    offset: int
    problem: str
    fatal: bool
    severity: str = "error"  # error | warning (validate)


@dataclass
class McapScan:
    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    profile: str = ""
    library: str = ""
    issues: list[ScanIssue] = field(default_factory=list)
    complete: bool = False  # footer + closing magic seen
    n_loose: int = 0  # Message records outside chunks (no CRC covers them)
    n_unchecked: int = 0  # chunks whose CRC field is 0 (not computed)


class _Cursor:
    __slots__ = ("b", "p")

    def __init__(self, b: bytes, p: int = 0):
        self.b = b
        self.p = p

    def u16(self) -> int:
        v = struct.unpack_from("<H", self.b, self.p)[0]
        self.p += 2
        return v

    def u32(self) -> int:
        v = struct.unpack_from("<I", self.b, self.p)[0]
        self.p += 4
        return v

    def u64(self) -> int:
        v = struct.unpack_from("<Q", self.b, self.p)[0]
        self.p += 8
        return v

    def raw(self, n: int) -> bytes:
        if self.p + n > len(self.b):
            raise struct.error("field runs past the end of its record")
        v = self.b[self.p:self.p + n]
        self.p += n
        return bytes(v)

    def s(self) -> str:
        return self.raw(self.u32()).decode("utf-8")

    def map_ss(self) -> dict[str, str]:
        end = self.u32() + self.p
        if end > len(self.b):
            raise struct.error("map runs past the end of its record")
        out = {}
        while self.p < end:
            k = self.s()
            out[k] = self.s()
        return out


def _parse_schema(c: bytes) -> SchemaRec:
    cu = _Cursor(c)
    sid = cu.u16()
    name = cu.s()
    enc = cu.s()
    data = cu.raw(cu.u32())
    return SchemaRec(sid, name, enc, data)


def _parse_channel(c: bytes) -> ChannelRec:
    cu = _Cursor(c)
    cid = cu.u16()
    sid = cu.u16()
    topic = cu.s()
    enc = cu.s()
    md = cu.map_ss()
    return ChannelRec(cid, sid, topic, enc, md)


def _parse_metadata(c: bytes) -> tuple[str, dict[str, str]]:
    cu = _Cursor(c)
    name = cu.s()
    return name, cu.map_ss()


def _split_records(buf: bytes, where: str, scan: McapScan) -> MessageBlock:
    """Walk the records of a chunk body; return its messages (schemas/channels go into ``scan``)."""
    n = len(buf)
    arr = np.frombuffer(buf, np.uint8)
    starts: list[int] = []
    lens: list[int] = []
    runs: list[tuple[int, int, int]] = []  # (first record start, stride, count) of equal-length message runs
    p = 0
    window = 16
    unpack = struct.unpack_from
    ar8 = np.arange(1, 9)
    while p < n:
        if p + 9 > n:
            raise McapFormatError(f"{where}: record header cut at byte {p} of {n}")
        op, ln = unpack("<BQ", buf, p)
        q = p + 9
        if q + ln > n:
            raise McapFormatError(f"{where}: record (opcode 0x{op:02x}) of {ln} bytes overruns the chunk")
        if op == OP_MESSAGE:
            # Fast path: consecutive message records of the same length form a run whose headers sit
            # at a fixed stride; verify them in one numpy step (each verified header proves where the
            # next record starts, so the verified prefix is exact).
            stride = 9 + ln
            maxj = min((n - p) // stride, window)
            if maxj >= 4:
                pos = p + stride * np.arange(maxj)
                ok = arr[pos] == OP_MESSAGE
                ok &= np.ascontiguousarray(arr[pos[:, None] + ar8]).view("<u8").ravel() == ln
                run = maxj if ok.all() else int(np.argmin(ok))
                window = min(window * 2, 1 << 16) if run == maxj else 16
                if run > 1:
                    runs.append((q, stride, run))
                    p += run * stride
                    continue
            starts.append(q)
            lens.append(ln)
        elif op == OP_SCHEMA:
            s = _parse_schema(buf[q:q + ln])
            scan.schemas.setdefault(s.id, s)  # the first definition of an id stands (as for the data section)
        elif op == OP_CHANNEL:
            c = _parse_channel(buf[q:q + ln])
            scan.channels.setdefault(c.id, c)
        p = q + ln
    st = np.asarray(starts, np.int64)
    ln = np.asarray(lens, np.int64)
    if runs:
        st = np.concatenate([st] + [q0 + s_ * np.arange(k, dtype=np.int64) for q0, s_, k in runs])
        ln = np.concatenate([ln] + [np.full(k, s_ - 9, np.int64) for _, s_, k in runs])
        o = np.argsort(st, kind="stable")  # keep file order
        st, ln = st[o], ln[o]
    if len(st) and ln.min() < MSG_FIXED:
        raise McapFormatError(f"{where}: message record shorter than its fixed header")
    idx = st[:, None] + np.arange(MSG_FIXED)[None, :]
    fixed = arr[idx] if len(st) else np.zeros((0, MSG_FIXED), np.uint8)
    fixed = np.ascontiguousarray(fixed)
    ch = fixed[:, 0:2].copy().view("<u2").ravel()
    lt = fixed[:, 6:14].copy().view("<u8").ravel()
    return MessageBlock(arr, ch, lt, st + MSG_FIXED, ln - MSG_FIXED)


def _plausible_header(buf, p: int, size: int) -> bool:
    """A record header at ``p`` of ``buf`` (the file from some base) whose opcode is defined and whose
    length stays inside the file."""
    if p + 9 > len(buf):
        return False
    op = buf[p]
    if op not in VALID_OPS:
        return False
    ln = struct.unpack_from("<Q", buf, p + 1)[0]
    return ln <= MAX_RECORD and p + 9 + ln <= size


def _resync(f, start: int, size: int) -> int | None:
    """Offset of the next record at or after ``start`` that begins a chain of valid records (two
    plausible headers in a row, or one that ends exactly at the footer / end of file); None if none.

    Used after a record whose header is damaged: compressed data almost never looks like two chained
    headers (a defined opcode and a length whose top 5 bytes are zero, twice), so the first chain is
    the real next record."""
    import mmap

    if start >= size:
        return None
    window = 1 << 24  # search 16 MiB at a time: memory stays bounded whatever the file size
    with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        for w0 in range(start, size, window):
            arr = np.frombuffer(mm, np.uint8, count=min(window, size - w0), offset=w0)
            cand = (np.flatnonzero((arr >= 0x01) & (arr <= 0x0F)) + w0).tolist()
            del arr
            for p in cand:
                if not _plausible_header(mm, p, size):
                    continue
                ln = struct.unpack_from("<Q", mm, p + 1)[0]
                q = p + 9 + ln
                if q == size or (mm[p] == OP_FOOTER and q + 8 == size) or _plausible_header(mm, q, size):
                    return p
    return None


def _cap_for(op: int) -> int:
    if op == OP_CHUNK:
        return MAX_RECORD
    if op in (OP_SCHEMA, OP_CHANNEL, OP_METADATA, OP_HEADER):
        return MAX_META_RECORD
    if op == OP_MESSAGE:
        return MAX_LOOSE_MESSAGE
    return 1 << 62  # not read (seeked over): any length inside the file


#: records the reader needs the content of (the others are seeked over: index and summary records
#: only repeat what the data section holds, attachments are not contract data)
_READ_OPS = frozenset((OP_HEADER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_METADATA, OP_FOOTER))
#: records whose loss loses no data (indexes, statistics, summary offsets, attachments)
_INDEX_OPS = frozenset((OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT, OP_ATTACHMENT_INDEX, OP_STATISTICS,
                        OP_METADATA_INDEX, OP_SUMMARY_OFFSET))


def scan_mcap(path: str | os.PathLike, scan: McapScan | None = None, *, chunk_filter=None,
              validate_crc: bool = True) -> Iterator[MessageBlock]:
    """Stream an MCAP file chunk by chunk, yielding :class:`MessageBlock`.

    Schema, channel and metadata records fill ``scan`` as they are met (before
    the messages that use them, as the spec requires). ``chunk_filter`` is
    reserved. Findings go to ``scan.issues``; they do not stop the scan:

    * truncation (the file ends inside a record, no closing magic): every complete record before
      the cut is yielded;
    * a damaged record header in the data section (undefined opcode, a length beyond the file or a
      cap, while the file still ends with the closing magic or a valid record follows): the scan
      resynchronises on the next chain of valid records (linear scan) and says how many bytes it
      skipped and whether they held data or only an index;
    * anything wrong after DataEnd (summary, footer): a warning; the data section is complete.

    Corrupt *data* raise :class:`McapFormatError`: a chunk whose CRC does not match, which does not
    decompress, or whose declared or actual size is beyond :data:`MAX_CHUNK_BYTES`.
    """
    path = os.fspath(path)
    scan = scan if scan is not None else McapScan()
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        magic = f.read(8)
        if magic != MAGIC:
            if len(magic) < 8 and MAGIC.startswith(magic):
                raise McapFormatError(f"file is empty or cut inside the MCAP magic ({size} bytes)")
            raise McapFormatError("not an MCAP file (bad magic bytes at offset 0)")
        f.seek(max(8, size - 8))
        ends_with_magic = size >= 16 and f.read(8) == MAGIC
        f.seek(8)
        pos = 8
        loose: list[tuple[int, int, bytes]] = []  # (channel, log_time, payload) outside chunks
        data_end = False

        def flush_loose():
            if not loose:
                return None
            buf = b"".join(p for _, _, p in loose)
            ln = np.array([len(p) for _, _, p in loose], np.int64)
            st = np.concatenate([[0], np.cumsum(ln)[:-1]]).astype(np.int64)
            blk = MessageBlock(np.frombuffer(buf, np.uint8), np.array([c for c, _, _ in loose], np.uint16),
                               np.array([t for _, t, _ in loose], np.uint64), st, ln, True)
            loose.clear()
            return blk

        def summary_issue(problem: str) -> None:
            scan.issues.append(ScanIssue(pos, f"summary/footer damaged: {problem}; the data section was read "
                                              "completely (ends with DataEnd), the summary is not needed",
                                         False, "warning"))

        while True:
            f.seek(pos)
            hdr = f.read(9)
            if len(hdr) == 0:
                if data_end:
                    summary_issue(f"file ends at byte {pos} without footer/closing magic")
                else:
                    scan.issues.append(ScanIssue(pos, "file ends without footer/closing magic (truncated: "
                                                      "recording was interrupted?); all complete records were "
                                                      "read", False))
                break
            if len(hdr) < 9:
                if data_end:
                    summary_issue(f"file ends inside a record header at byte {pos}")
                else:
                    scan.issues.append(ScanIssue(pos, f"file truncated inside a record header at byte {pos} "
                                                      f"of {size}; the records before it were read", False))
                break
            op, ln = struct.unpack("<BQ", hdr)
            defined = op in VALID_OPS or op >= 0x80
            overrun = pos + 9 + ln > size
            if data_end:
                if not defined or overrun:
                    summary_issue(f"record at byte {pos} has opcode 0x{op:02x} and length {ln} (file: {size} bytes)")
                    break
                if op == OP_FOOTER:
                    f.seek(pos + 9 + ln)
                    if f.read(8) != MAGIC:
                        summary_issue("closing magic missing or damaged after the footer")
                    else:
                        scan.complete = True
                    break
                pos += 9 + ln
                continue
            if not defined or overrun or ln > _cap_for(op):
                cut = overrun and defined and not ends_with_magic
                nxt = None if cut else _resync(f, pos + 1, size)
                if nxt is None:
                    if cut or overrun:
                        scan.issues.append(ScanIssue(pos, f"file truncated inside a record (opcode 0x{op:02x}) at "
                                                          f"byte {pos} of {size}: its {ln} bytes are not all there; "
                                                          "the records before it were read", False))
                        break
                    if ln > _cap_for(op) and defined:
                        raise McapFormatError(f"record at byte {pos} (opcode 0x{op:02x}) declares {ln} bytes, above "
                                              f"the cap of {_cap_for(op)} bytes for this record kind")
                    raise McapFormatError(f"corrupt record at byte {pos}: opcode 0x{op:02x}, length {ln}, and no "
                                          "valid record after it")
                index_only = op in _INDEX_OPS
                scan.issues.append(ScanIssue(
                    pos, f"corrupt record header at byte {pos} (opcode 0x{op:02x}, length {ln}"
                         + (f", beyond the file's {size} bytes" if overrun else "") + "): not a truncation (the file "
                         f"{'ends with the closing magic' if ends_with_magic else 'goes on with valid records'}); "
                         f"skipped {nxt - pos} bytes to the next valid record at byte {nxt}"
                         + ("; the damaged record was an index record, no data lost" if index_only else
                            "; messages in the skipped bytes are lost (dropouts show where)"),
                    False, "warning" if index_only else "error"))
                pos = nxt
                continue
            where = f"record at byte {pos}"
            if op not in _READ_OPS:
                if op == OP_DATA_END:
                    data_end = True
                pos += 9 + ln
                continue
            content = f.read(ln)
            pos += 9 + ln
            try:
                if op == OP_CHUNK:
                    blk = flush_loose()
                    if blk is not None:
                        yield blk
                    cu = _Cursor(content)
                    cu.u64(), cu.u64()
                    usize = cu.u64()
                    crc = cu.u32()
                    comp = cu.s()
                    clen = cu.u64()
                    if usize > MAX_CHUNK_BYTES:
                        raise McapFormatError(f"chunk {where} declares {usize} uncompressed bytes, above the cap "
                                              f"of {MAX_CHUNK_BYTES} (MAX_CHUNK_BYTES; contract writers make chunks "
                                              "of a few MiB): decompression bomb or corrupt size")
                    data = cu.raw(clen)
                    try:
                        body = _decompress(data, comp, usize)
                    except McapFormatError:
                        raise
                    except Exception as e:  # zstd/lz4 errors have no common base
                        raise McapFormatError(f"chunk {where} cannot be decompressed ({comp}): {e}") from None
                    if len(body) != usize:
                        raise McapFormatError(f"chunk {where}: decompresses to "
                                              f"{'more than ' if len(body) > usize else ''}{len(body)} bytes, "
                                              f"header says {usize}")
                    if not crc:
                        scan.n_unchecked += 1
                    if validate_crc and crc and zlib.crc32(body) != crc:
                        raise McapFormatError(f"chunk {where}: CRC mismatch (corrupt bytes)")
                    yield _split_records(body, f"chunk {where}", scan)
                elif op == OP_MESSAGE:
                    cid, _seq, lt, _pt = struct.unpack_from("<HIQQ", content, 0)
                    loose.append((cid, lt, content[MSG_FIXED:]))
                    scan.n_loose += 1
                elif op == OP_SCHEMA:
                    s = _parse_schema(content)
                    scan.schemas.setdefault(s.id, s)
                elif op == OP_CHANNEL:
                    c = _parse_channel(content)
                    scan.channels.setdefault(c.id, c)
                elif op == OP_METADATA:
                    name, md = _parse_metadata(content)
                    scan.metadata[name] = md
                elif op == OP_HEADER:
                    cu = _Cursor(content)
                    scan.profile = cu.s()
                    scan.library = cu.s()
                elif op == OP_FOOTER:
                    tail = f.read(8)
                    if tail != MAGIC:
                        scan.issues.append(ScanIssue(pos, "closing magic missing or damaged after the footer", False))
                    else:
                        scan.complete = True
                    break
            except (struct.error, UnicodeDecodeError) as e:
                raise McapFormatError(f"corrupt {where} (opcode 0x{op:02x}): {e}") from None
        blk = flush_loose()
        if blk is not None:
            yield blk
    if scan.n_loose or scan.n_unchecked:
        what = (f"{scan.n_loose} messages outside chunks" if scan.n_loose else "") + \
               (" and " if scan.n_loose and scan.n_unchecked else "") + \
               (f"{scan.n_unchecked} chunks without a CRC" if scan.n_unchecked else "")
        scan.issues.append(ScanIssue(0, f"{what}: MCAP has no checksum for these bytes, so a flipped bit cannot be "
                                        "detected; values are only plausibility-checked", False, "warning"))


def read_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """Every Metadata record of an MCAP file (name -> key/value map), without decompressing a chunk.

    Walks the data section record by record (length prefixes, ``seek`` over chunks and
    messages) up to DataEnd. For consumers that need ``hd_mission`` *before* the messages:
    other tools (``mcap-ros2-support``, ``rosbags``, ``ros2 bag``) write metadata records
    after the chunks, so a streaming reader only meets them at the end. Raises
    :class:`McapFormatError` (naming the byte) on a non-MCAP file or a damaged metadata record;
    a truncated file gives what precedes the cut.
    """
    out: dict[str, dict[str, str]] = {}
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        if f.read(8) != MAGIC:
            raise McapFormatError("not an MCAP file (bad magic bytes at offset 0)")
        pos = 8
        while pos + 9 <= size:
            f.seek(pos)
            op, ln = struct.unpack("<BQ", f.read(9))
            if op == OP_DATA_END or op == OP_FOOTER or pos + 9 + ln > size:
                break
            if op == OP_METADATA:
                if ln > MAX_META_RECORD:
                    raise McapFormatError(f"metadata record at byte {pos} declares {ln} bytes, above the cap of "
                                          f"{MAX_META_RECORD}")
                try:
                    name, md = _parse_metadata(f.read(ln))
                except (struct.error, UnicodeDecodeError) as e:
                    raise McapFormatError(f"corrupt metadata record at byte {pos}: {e}") from None
                out[name] = md
            pos += 9 + ln
    return out


def payloads(block: MessageBlock, sel: np.ndarray) -> list[bytes]:
    """Payload bytes of the selected messages of a block (for the generic decoder)."""
    b = block.buf
    return [b[s:s + n].tobytes() for s, n in zip(block.start[sel].tolist(), block.length[sel].tolist())]


def gather_rows(block: MessageBlock, sel: np.ndarray, width: int) -> np.ndarray:
    """(n, width) uint8 array of the payloads ``sel`` (all of length ``width``)."""
    st = block.start[sel]
    if len(st) == 0:
        return np.zeros((0, width), np.uint8)
    if len(st) > 1 and np.all(np.diff(st) == np.diff(st)[0]) and np.diff(st)[0] >= width:
        stride = int(np.diff(st)[0])
        base = np.lib.stride_tricks.as_strided(block.buf[int(st[0]):], shape=(len(st), width), strides=(stride, 1))
        return np.array(base)
    return block.buf[st[:, None] + np.arange(width)[None, :]]


__all__ = ["McapFileWriter", "McapFormatError", "McapScan", "MessageBlock", "scan_mcap", "message_records",
           "payloads", "gather_rows", "io"]


def recover_mcap(src: str | os.PathLike, dst: str | os.PathLike, compression: str = "zstd") -> dict:
    """Write a finalised copy of an MCAP file that lacks its summary/footer (a recorder killed with
    SIGKILL, a power cut): every complete chunk and loose message before the cut, with the schemas,
    channels and metadata met before it, then DataEnd, summary and footer, so any MCAP reader
    (``mcap.reader.make_reader``, ``ros2 bag``) opens it. Damaged records in the data section are
    skipped as :func:`scan_mcap` does. Returns counts and the scan's issues. ``dst`` must differ from
    ``src``."""
    src, dst = os.fspath(src), os.fspath(dst)
    if os.path.abspath(src) == os.path.abspath(dst):
        raise ValueError(f"{dst}: recovery writes a new file; give another output path")
    scan = McapScan()
    w = None
    n_msgs = n_chunks = 0
    seen_s: set[int] = set()
    seen_c: set[int] = set()
    seen_m: set[str] = set()

    def sync():
        nonlocal w
        if w is None:
            w = McapFileWriter(dst, profile=scan.profile or "ros2", library=(scan.library or "") + " (recovered)",
                               compression=compression)
        for sid, s in scan.schemas.items():
            if sid not in seen_s:
                w.add_schema(sid, s.name, s.encoding, s.data)
                seen_s.add(sid)
        for cid, c in scan.channels.items():
            if cid not in seen_c:
                w.add_channel(cid, c.schema_id, c.topic, c.message_encoding, c.metadata)
                seen_c.add(cid)
        for name, md in scan.metadata.items():
            if name not in seen_m:
                w.add_metadata(name, md)
                seen_m.add(name)

    try:
        for blk in scan_mcap(src, scan):
            sync()
            blocks = []
            for cid in np.unique(blk.channel).tolist():
                sel = np.flatnonzero(blk.channel == cid)
                st = blk.start[sel] - MSG_FIXED - 9
                en = blk.start[sel] + blk.length[sel]
                buf = blk.buf
                if blk.loose:  # messages outside chunks: rebuild their records
                    recs = [_record(OP_MESSAGE, struct.pack("<HIQQ", cid, 0, int(t), int(t)) + buf[s:s + n].tobytes())
                            for s, n, t in zip(blk.start[sel].tolist(), blk.length[sel].tolist(),
                                               blk.log_time[sel].tolist())]
                else:
                    recs = [buf[a:b].tobytes() for a, b in zip(st.tolist(), en.tolist())]
                blocks.append((cid, blk.log_time[sel], recs))
                n_msgs += len(sel)
            w.write_chunk(blocks)
            n_chunks += 1
        sync()
    finally:
        if w is not None:
            w.close()
    return {"messages": n_msgs, "chunks": n_chunks, "complete_before": scan.complete,
            "issues": [i.problem for i in scan.issues]}
