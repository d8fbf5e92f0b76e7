"""The MCAP layer of an mjskill recording, read with the checks of mjskill's own reader
(src/record/scan.rs), for examples/demos.py: a damaged file is refused, a file cut short
(a killed or still running ``mjskill rollout``) is read up to the cut.

The file is read record by record, none longer than :data:`MAX_RECORD` and no length read
from the file used before it was checked against the record holding it, so memory stays
within a few records whatever the file declares. Checked, as src/record/scan.rs checks them:

* every chunk's CRC (a chunk without one is damage), its compression (zstd or none), its
  uncompressed size (at most :data:`MAX_RECORD`, decompressed no further), its record length
  against its header, its time range against its messages, and the message indexes after it
  against its messages;
* the data section's CRC (in the data end record) and the summary section's (in the footer)
  of a file that was closed, and its end magic;
* which records may stand where (a header first, messages only inside chunks).

The end of the file decides between cut and damaged, as there: a file that ends with the end
magic was closed, so running out of bytes is damage; in one without it, a last record that is
the consistent beginning of a record is a cut, anything else damage.
"""

from __future__ import annotations

import io
import struct
import zlib

MAGIC = b"\x89MCAP0\r\n"
#: The largest record, and the largest decompressed chunk, read (64 MiB): mjskill's limit.
MAX_RECORD = 64 << 20
#: Opcode and length prefix of every record.
PREFIX = 9

HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = range(1, 9)
ATTACHMENT, ATTACHMENT_INDEX, STATISTICS, METADATA, METADATA_INDEX = range(9, 14)
SUMMARY_OFFSET, DATA_END = 14, 15
_NAMES = {HEADER: "header", FOOTER: "footer", SCHEMA: "schema", CHANNEL: "channel",
          MESSAGE: "message", CHUNK: "chunk", MESSAGE_INDEX: "message index",
          CHUNK_INDEX: "chunk index", ATTACHMENT: "attachment",
          ATTACHMENT_INDEX: "attachment index", STATISTICS: "statistics",
          METADATA: "metadata", METADATA_INDEX: "metadata index",
          SUMMARY_OFFSET: "summary offset", DATA_END: "data end"}
_SUMMARY = {SCHEMA, CHANNEL, CHUNK_INDEX, ATTACHMENT_INDEX, METADATA_INDEX, STATISTICS,
            SUMMARY_OFFSET}


def op_name(opcode):
    return _NAMES.get(opcode, f"unknown (opcode {opcode:#04x})")


class Damaged(Exception):
    """The file is damaged (not merely cut short): a CRC or structure check failed at
    ``offset``."""

    def __init__(self, offset, detail):
        super().__init__(f"at byte offset {offset}: {detail}")
        self.offset = offset
        self.detail = detail


class NotRecording(Exception):
    """An MCAP file that is not an mjskill recording (its header's profile)."""


class _Bad(Exception):
    """A record that does not parse (turned into Damaged by the caller)."""


class _Body:
    """Bounds-checked little-endian fields of a record."""

    def __init__(self, b):
        self.b, self.i = b, 0

    def take(self, n):
        if n < 0 or self.i + n > len(self.b):
            raise _Bad(f"a field at byte {self.i} of the record runs past its end "
                       f"({len(self.b)} bytes)")
        out = self.b[self.i:self.i + n]
        self.i += n
        return out

    def u16(self):
        return struct.unpack("<H", self.take(2))[0]

    def u32(self):
        return struct.unpack("<I", self.take(4))[0]

    def u64(self):
        return struct.unpack("<Q", self.take(8))[0]

    def string(self):
        try:
            return bytes(self.take(self.u32())).decode("utf-8")
        except UnicodeDecodeError:
            raise _Bad("a string that is not UTF-8") from None

    def string_map(self):
        inner = _Body(self.take(self.u32()))
        out = {}
        while inner.i < len(inner.b):
            k = inner.string()
            out[k] = inner.string()
        return out

    def done(self):
        return self.i == len(self.b)


def _u32_at(b, i):
    return struct.unpack_from("<I", b, i)[0] if i + 4 <= len(b) else None


def _u64_at(b, i):
    return struct.unpack_from("<Q", b, i)[0] if i + 8 <= len(b) else None


def _decompress(compression, data, size):
    """A chunk's records: at most ``size`` bytes, never more, whatever the data holds."""
    if compression == "":
        return bytes(data)
    import zstandard

    reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data))
    out = reader.read(size + 1)
    return out


class _Scan:
    def __init__(self, f, size, path, on_metadata, on_message):
        self.f, self.size, self.path = f, size, path
        self.on_metadata, self.on_message = on_metadata, on_message
        self.offset = 8
        self.section = "data"
        self.header = False
        self.chunks = 0
        self.schemas = set()
        self.channels = {}
        self.pending = None  # (chunk offset, {channel: sorted [(log_time, offset)]})
        self.last = None  # (offset, opcode) of the last complete record

    def close_pending(self):
        if self.pending is not None:
            chunk, need = self.pending
            self.pending = None
            if need:
                raise Damaged(chunk, f"the chunk at byte offset {chunk} has no message index "
                                     f"for its messages on channel {min(need)}")

    def register(self, opcode, body):
        b = _Body(body)
        if opcode == SCHEMA:
            sid = b.u16()
            b.string()
            b.string()
            b.take(b.u32())
            if sid == 0:
                raise _Bad("schema with id 0")
            self.schemas.add(sid)
        else:
            cid, sid = b.u16(), b.u16()
            topic = b.string()
            b.string()
            b.string_map()
            if sid != 0 and sid not in self.schemas:
                raise _Bad(f"channel {cid} names unknown schema {sid}")
            self.channels[cid] = topic
        if not b.done():
            raise _Bad("bytes after its last field")

    def record(self, opcode, body):
        at = self.offset
        if not self.header and opcode != HEADER:
            raise Damaged(at, f"the first record is a {op_name(opcode)} record, not a header")
        if opcode != MESSAGE_INDEX:
            self.close_pending()
        try:
            self._record(opcode, body)
        except _Bad as e:
            raise Damaged(at, f"{op_name(opcode)} record: {e}") from None

    def _record(self, opcode, body):
        at = self.offset
        if self.section == "data" and opcode == HEADER:
            if self.header:
                raise Damaged(at, "a second header record")
            self.header = True
            b = _Body(body)
            profile = b.string()
            b.string()
            if profile != "mjskill":
                raise NotRecording(f"its MCAP profile is {profile!r}, not 'mjskill': not a "
                                   "recording of `mjskill rollout`")
        elif self.section == "data" and opcode == METADATA:
            b = _Body(body)
            name = b.string()
            m = b.string_map()
            if not b.done():
                raise _Bad("bytes after its last field")
            self.on_metadata(name, m, at)
        elif self.section == "data" and opcode in (SCHEMA, CHANNEL):
            self.register(opcode, body)
        elif self.section == "data" and opcode == CHUNK:
            self.chunk(body)
        elif self.section == "data" and opcode == MESSAGE_INDEX:
            b = _Body(body)
            cid = b.u16()
            entries = _Body(b.take(b.u32()))
            got = []
            while entries.i < len(entries.b):
                got.append((entries.u64(), entries.u64()))
            if self.pending is None:
                raise Damaged(at, f"message index of channel {cid} follows no chunk")
            chunk, need = self.pending
            if need.pop(cid, None) != sorted(got):
                raise Damaged(at, f"message index of channel {cid} does not match the "
                                  f"messages of the chunk at byte offset {chunk}")
        elif self.section == "data" and opcode == DATA_END:
            saved = _Body(body).u32()
            if saved != 0 and saved != self.crc:
                raise Damaged(at, f"data section CRC mismatch: the data end record holds "
                                  f"{saved:08x}, the data section has {self.crc:08x}")
            self.section = "summary"
        elif self.section == "summary" and opcode in _SUMMARY:
            pass  # covered by the summary CRC, checked at the footer
        elif self.section == "summary" and opcode == FOOTER:
            if len(body) != 20:
                raise Damaged(at, f"footer of {len(body)} bytes, not 20")
            saved = _u32_at(body, 16)
            if saved != 0 and saved != self.summary_crc:
                raise Damaged(at, f"summary section CRC mismatch: the footer holds "
                                  f"{saved:08x}, the summary has {self.summary_crc:08x}")
            self.section = "end"
        else:
            raise Damaged(at, f"unexpected {op_name(opcode)} record in the {self.section} "
                              "section")

    def chunk(self, body):
        offset, ordinal = self.offset, self.chunks
        self.chunks += 1

        def bad(detail):
            return Damaged(offset, f"chunk {ordinal}: {detail}")

        try:
            b = _Body(body)
            start, end, usize, crc = b.u64(), b.u64(), b.u64(), b.u32()
            compression = b.string()
            csize = b.u64()
        except _Bad as e:
            raise bad(str(e)) from None
        header_len = 40 + len(compression.encode())
        if header_len + csize != len(body):
            raise bad(f"record length {len(body)} does not match its {header_len}-byte header "
                      f"and {csize} compressed bytes")
        if usize > MAX_RECORD:
            raise bad(f"declares {usize} uncompressed bytes, more than the "
                      f"{MAX_RECORD >> 20} MiB limit")
        if crc == 0:
            raise bad("has no CRC (mjskill writes one for every chunk)")
        if compression not in ("zstd", ""):
            raise bad(f"unknown compression {compression!r}")
        try:
            data = _decompress(compression, body[header_len:], usize)
        except Exception as e:  # noqa: BLE001 - zstandard's errors for bad data vary
            raise bad(f"does not decompress ({type(e).__name__}: {e})") from None
        if len(data) != usize:
            raise bad(f"declares {usize} uncompressed bytes, its data decompresses to "
                      f"{'more' if len(data) > usize else len(data)}")
        calc = zlib.crc32(data)
        if calc != crc:
            raise bad(f"CRC mismatch: the chunk records CRC {crc:08x}, its data has "
                      f"{calc:08x}")
        need, times, i = {}, None, 0
        where = f"chunk {ordinal} at byte offset {offset}"
        while i < len(data):
            if i + PREFIX > len(data):
                raise bad(f"a record at byte {i} of its data runs past its end")
            opcode = data[i]
            n = struct.unpack_from("<Q", data, i + 1)[0]
            if n > len(data) - i - PREFIX:
                raise bad(f"a record at byte {i} of its data runs past its end")
            rec = data[i + PREFIX:i + PREFIX + n]
            try:
                if opcode == MESSAGE:
                    r = _Body(rec)
                    cid, _seq, log_time, _pub = r.u16(), r.u32(), r.u64(), r.u64()
                    if cid not in self.channels:
                        raise _Bad(f"message on unknown channel {cid}")
                    need.setdefault(cid, []).append((log_time, i))
                    times = (log_time, log_time) if times is None else (
                        min(times[0], log_time), max(times[1], log_time))
                    self.on_message(self.channels[cid], rec[r.i:], where)
                elif opcode in (SCHEMA, CHANNEL):
                    self.register(opcode, rec)
                else:
                    raise _Bad(f"unexpected {op_name(opcode)} record")
            except _Bad as e:
                raise bad(f"record at byte {i} of its data: {e}") from None
            i += PREFIX + n
        if (start, end) != (times or (0, 0)):
            s, e = times or (0, 0)
            raise bad(f"header time range {start}..{end} differs from its messages' {s}..{e}")
        self.pending = (offset, {k: sorted(v) for k, v in need.items()})

    def tail(self, closed):
        """The file ran out of bytes at ``self.offset``: a cut (returns its description) or
        damage (raises)."""
        at, size = self.offset, self.size
        if closed:
            raise Damaged(at, f"the record at byte offset {at} runs past the end of the file, "
                              "which was closed properly (it ends with the end magic)")
        avail = size - at
        self.f.seek(at)
        tail = self.f.read(min(avail, PREFIX + 4096))
        if self.section == "end":
            if MAGIC.startswith(tail):
                return f"the file ends inside its end magic at byte {size}"
            raise Damaged(at, "bad end magic")
        if avail == 0:
            if self.last is None:
                return f"the file ends at byte {size}, after the magic"
            return (f"the file ends at byte {size}, after the {op_name(self.last[1])} record "
                    f"at byte offset {self.last[0]}")
        if len(tail) < PREFIX:
            return f"the file ends at byte {size}, inside the record header at byte offset {at}"
        opcode = tail[0]
        rlen = struct.unpack_from("<Q", tail, 1)[0]
        body = tail[PREFIX:]

        def damaged(detail):
            return Damaged(at, f"the last record (at byte offset {at}, {op_name(opcode)}) is "
                               f"not the beginning of a record cut short: {detail}")

        if self.section == "data":
            expected = opcode in (CHUNK, MESSAGE_INDEX, METADATA, DATA_END) or (
                opcode == HEADER and not self.header)
        else:
            expected = opcode in _SUMMARY or opcode == FOOTER
        if not expected:
            raise damaged("no such record can stand here")
        if rlen <= avail - PREFIX:
            raise damaged(f"it is complete ({rlen} bytes) yet does not parse")
        if opcode == DATA_END and rlen != 4:
            raise damaged(f"length {rlen}, not 4")
        if opcode == FOOTER and rlen != 20:
            raise damaged(f"length {rlen}, not 20")
        if opcode == CHUNK:
            clen = _u32_at(body, 28)
            if clen is not None:
                if 40 + clen > rlen:
                    raise damaged(f"compression name of {clen} bytes")
                name = body[32:32 + clen]
                if len(name) == clen and name not in (b"zstd", b""):
                    raise damaged("unknown compression")
                csize = _u64_at(body, 32 + clen)
                if csize is not None and rlen != 40 + clen + csize:
                    raise damaged(f"length {rlen} does not match its header and {csize} "
                                  "compressed bytes")
            usize = _u64_at(body, 16)
            if usize is not None and usize > MAX_RECORD:
                raise damaged(f"{usize} uncompressed bytes")
            if _u32_at(body, 24) == 0:
                raise damaged("no CRC")
        elif opcode == MESSAGE_INDEX:
            n = _u32_at(body, 2)
            if n is not None and (rlen != 6 + n or n % 16 != 0):
                raise damaged(f"length {rlen} for {n} bytes of entries")
        elif opcode == METADATA:
            n = _u32_at(body, 0)
            if n is not None:
                if 8 + n > rlen:
                    raise damaged(f"name of {n} bytes")
                m = _u32_at(body, 4 + n)
                if m is not None and rlen != 8 + n + m:
                    raise damaged(f"length {rlen} for a {m}-byte map")
        if rlen > MAX_RECORD:
            raise damaged(f"{rlen} bytes")
        return (f"the file ends at byte {size}, inside the {op_name(opcode)} record at byte "
                f"offset {at} ({avail} of its {PREFIX + rlen} bytes are present)")

    def run(self):
        """(complete, cut): whether the file was read to its end magic, and where it was cut
        short (None if it was not)."""
        f, size = self.f, self.size
        closed = False
        if size >= 16:
            f.seek(size - 8)
            closed = f.read(8) == MAGIC
        f.seek(0)
        self.crc = zlib.crc32(f.read(8))
        self.summary_crc = 0
        while True:
            if self.section == "end":
                rest = f.read(9)
                if rest == MAGIC:
                    return True, None
                if len(rest) < 8:
                    return False, self.tail(closed)
                raise Damaged(self.offset, "bad end magic" if rest[:8] != MAGIC
                              else "bytes after the end magic")
            head = f.read(PREFIX)
            if len(head) < PREFIX:
                return False, self.tail(closed)
            opcode = head[0]
            n = struct.unpack_from("<Q", head, 1)[0]
            if n > MAX_RECORD:
                raise Damaged(self.offset, f"in the record at byte offset {self.offset}: "
                                           f"{op_name(opcode)} record declares {n} bytes, more "
                                           f"than the {MAX_RECORD >> 20} MiB limit")
            if n > size - self.offset - PREFIX:
                return False, self.tail(closed)
            body = f.read(n)
            if len(body) < n:
                return False, self.tail(closed)
            if self.section == "data" and opcode != DATA_END:
                self.crc = zlib.crc32(body, zlib.crc32(head, self.crc))
            elif self.section == "summary":
                covered = body[:16] if opcode == FOOTER else body
                self.summary_crc = zlib.crc32(covered, zlib.crc32(head, self.summary_crc))
            self.record(opcode, body)
            self.last = (self.offset, opcode)
            self.offset += PREFIX + n


def scan(f, size, path, on_metadata, on_message):
    """Reads the MCAP file ``f`` (open, binary, ``size`` bytes, named ``path`` in messages)
    from start to end, handing every metadata record to ``on_metadata(name, map, offset)``
    and every message to ``on_message(topic, data, where)`` as it is read. Returns
    (complete, cut): whether the file was read to its end magic with every check passing, and
    where it was cut short (None if it was not). Damage is a :class:`Damaged` naming the byte
    offset (and the chunk); another profile a :class:`NotRecording`. The callbacks' errors
    stop the scan and are raised as they are."""
    return _Scan(f, size, path, on_metadata, on_message).run()
