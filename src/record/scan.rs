//! Streaming, bounded and damage-aware reading of the MCAP layer of a recording.
//!
//! The file is read in pieces of at most 1 MiB through the `mcap` crate's sans-io
//! [`LinearReader`], with a record-length limit ([`MAX_RECORD`]), data- and summary-section CRC
//! validation, and every chunk decompressed into a second reader that validates its CRC before
//! yielding a single record (`prevalidate_chunk_crcs`). Memory therefore stays below a few
//! times [`MAX_RECORD`] whatever the file holds, and no length read from the file is allocated
//! before it has been checked.
//!
//! On top of the crate's checks, everything the `mjskill` writer produces is checked for
//! consistency, so that a damaged byte anywhere in a closed file, and anywhere but the header's
//! `library` string in a file cut short, is found: a chunk record's length must equal its header
//! plus its compressed size, a chunk must carry a CRC, its time range must be that of its
//! messages, and the message indexes after it must list exactly its messages.
//!
//! The end of the file decides between "cut short" and "damaged": a file whose last bytes are
//! the end magic was closed properly, so running out of bytes means damage; in a
//! file without them, a last record that is the consistent beginning of a record (e.g. a chunk
//! whose header matches its length) is a cut, and anything else is damage.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::McapError;

use super::RecordError;

/// Largest record, and largest decompressed chunk, a reader accepts (64 MiB). The recorder
/// closes chunks at about 1 MiB and refuses messages above [`MAX_MESSAGE`], so every file it
/// writes stays within this limit.
pub const MAX_RECORD: usize = 64 << 20;
/// Largest message payload the recorder writes (32 MiB).
pub const MAX_MESSAGE: usize = 32 << 20;
/// Bytes handed to the reader per read call.
const PIECE: usize = 1 << 20;
/// Opcode and length prefix of every record.
const PREFIX: u64 = 9;

/// Where a record lies: its byte offset in the file, and for the records inside a chunk, the
/// chunk's ordinal (0-based, in file order) and offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct At {
    /// Offset of the record, or of the chunk holding it.
    pub offset: u64,
    /// (ordinal, file offset) of the chunk holding the record.
    pub chunk: Option<(usize, u64)>,
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.chunk {
            Some((k, off)) => write!(f, "chunk {k} at byte offset {off}"),
            None => write!(f, "byte offset {}", self.offset),
        }
    }
}

/// One record handed to the consumer of [`scan`].
#[derive(Debug)]
pub(crate) enum Item<'a> {
    /// The header record.
    Header {
        /// Profile.
        profile: &'a str,
        /// Writing library.
        library: &'a str,
    },
    /// A metadata record.
    Metadata {
        /// Record name.
        name: &'a str,
        /// Key-value pairs.
        map: &'a BTreeMap<String, String>,
    },
    /// A message with its channel's description.
    Message {
        /// Channel topic.
        topic: &'a str,
        /// Schema name ("" without schema).
        schema: &'a str,
        /// Message encoding.
        encoding: &'a str,
        /// Log time (ns).
        log_time: u64,
        /// Payload.
        data: &'a [u8],
    },
}

/// How a scan ended without an error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct End {
    /// The file was read up to its footer and end magic, every CRC matching.
    pub complete: bool,
    /// The file was cut short: the offset where it ends and what it ends in.
    pub truncated: Option<(u64, String)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Section {
    Data,
    Summary,
    EndMagic,
}

/// Message index entries (log time, offset in the chunk) by channel.
type IndexEntries = BTreeMap<u16, Vec<(u64, u64)>>;

struct Channel {
    topic: String,
    schema: String,
    encoding: String,
}

/// The state of a scan, apart from the reader.
struct Scan<'p> {
    path: &'p Path,
    /// Offset of the next top-level record.
    offset: u64,
    section: Section,
    header: bool,
    chunks: usize,
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Channel>,
    /// Message index entries the last chunk needs, by channel: (chunk offset, entries).
    pending: Option<(u64, IndexEntries)>,
    /// Offset of the last complete record (for messages about cuts).
    last: Option<(u64, u8)>,
}

/// A human name of a record opcode.
fn op_name(opcode: u8) -> String {
    match opcode {
        op::HEADER => "header".into(),
        op::FOOTER => "footer".into(),
        op::SCHEMA => "schema".into(),
        op::CHANNEL => "channel".into(),
        op::MESSAGE => "message".into(),
        op::CHUNK => "chunk".into(),
        op::MESSAGE_INDEX => "message index".into(),
        op::CHUNK_INDEX => "chunk index".into(),
        op::ATTACHMENT => "attachment".into(),
        op::ATTACHMENT_INDEX => "attachment index".into(),
        op::STATISTICS => "statistics".into(),
        op::METADATA => "metadata".into(),
        op::METADATA_INDEX => "metadata index".into(),
        op::SUMMARY_OFFSET => "summary offset".into(),
        op::DATA_END => "data end".into(),
        other => format!("unknown (opcode {other:#04x})"),
    }
}

fn mcap_detail(e: &McapError) -> String {
    match e {
        McapError::BadChunkCrc { saved, calculated } => format!(
            "CRC mismatch: the chunk records CRC {saved:08x}, its data has {calculated:08x}"
        ),
        McapError::BadDataCrc { saved, calculated } => format!(
            "data section CRC mismatch: the data end record holds {saved:08x}, the data \
             section has {calculated:08x}"
        ),
        McapError::BadSummaryCrc { saved, calculated } => format!(
            "summary section CRC mismatch: the footer holds {saved:08x}, the summary has \
             {calculated:08x}"
        ),
        McapError::RecordTooLarge { opcode, len } => format!(
            "{} record declares {len} bytes, more than the {} MiB limit",
            op_name(*opcode),
            MAX_RECORD >> 20
        ),
        McapError::ChunkTooLarge(n) => format!(
            "chunk declares {n} bytes, more than the {} MiB limit",
            MAX_RECORD >> 20
        ),
        McapError::UnexpectedEof => "the data ends in the middle of a record".into(),
        McapError::UnexpectedEoc => "a record runs past the end of its chunk".into(),
        McapError::BadMagic => "bad end magic".into(),
        McapError::BytesAfterEndMagic => "bytes after the end magic".into(),
        other => other.to_string(),
    }
}

/// Checks that every length-prefixed field of a record lies inside it, so that parsing it
/// allocates no more than the record's own size.
fn check_lengths(opcode: u8, body: &[u8]) -> Result<(), BadRecord> {
    struct W<'a>(&'a [u8], usize);
    impl W<'_> {
        fn skip(&mut self, n: usize) -> Result<(), BadRecord> {
            match self.1.checked_add(n) {
                Some(end) if end <= self.0.len() => {
                    self.1 = end;
                    Ok(())
                }
                _ => Err(BadRecord::FieldPastEnd {
                    at: self.1,
                    len: self.0.len(),
                }),
            }
        }
        fn u32(&mut self) -> Result<usize, BadRecord> {
            let at = self.1;
            self.skip(4)?;
            let mut b = [0u8; 4];
            b.copy_from_slice(&self.0[at..at + 4]);
            Ok(u32::from_le_bytes(b) as usize)
        }
        fn string(&mut self) -> Result<(), BadRecord> {
            let n = self.u32()?;
            self.skip(n)
        }
        fn string_map(&mut self) -> Result<(), BadRecord> {
            let n = self.u32()?;
            let end = self.1;
            self.skip(n)?;
            let mut inner = W(&self.0[end..end + n], 0);
            while inner.1 < n {
                inner.string()?;
                inner.string()?;
            }
            Ok(())
        }
    }
    let mut w = W(body, 0);
    match opcode {
        op::HEADER => {
            w.string()?;
            w.string()
        }
        op::METADATA => {
            w.string()?;
            w.string_map()
        }
        op::SCHEMA => {
            w.skip(2)?;
            w.string()?;
            w.string()?;
            w.string()
        }
        op::CHANNEL => {
            w.skip(4)?;
            w.string()?;
            w.string()?;
            w.string_map()
        }
        op::CHUNK => {
            w.skip(28)?;
            w.string()?;
            w.skip(8)
        }
        _ => Ok(()),
    }
}

/// Why a record does not parse or register (the detail of [`RecordError::Corrupt`]).
#[derive(Debug, thiserror::Error)]
enum BadRecord {
    /// A length-prefixed field runs past the record.
    #[error("a field at byte {at} of the record runs past its end ({len} bytes)")]
    FieldPastEnd {
        /// Where the field starts.
        at: usize,
        /// The record's length.
        len: usize,
    },
    /// The mcap crate's parse error, worded by [`mcap_detail`].
    #[error("{0}")]
    Mcap(String),
    /// A schema record with the reserved id 0.
    #[error("schema with id 0")]
    SchemaIdZero,
    /// A channel whose schema was not defined before it.
    #[error("channel {channel} names unknown schema {schema}")]
    UnknownSchema {
        /// The channel id.
        channel: u16,
        /// The schema id.
        schema: u16,
    },
    /// Another record where a schema or channel was expected.
    #[error("not a schema or channel")]
    NotSchemaOrChannel,
}

/// Parses a record whose length fields were checked.
fn parse(opcode: u8, body: &[u8]) -> Result<Record<'_>, BadRecord> {
    check_lengths(opcode, body)?;
    mcap::parse_record(opcode, body).map_err(|e| BadRecord::Mcap(mcap_detail(&e)))
}

/// Reads up to `buf.len()` bytes, retrying interrupted reads; 0 means end of file.
fn read_some(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match file.read(buf) {
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            r => return r,
        }
    }
}

impl Scan<'_> {
    fn corrupt(&self, offset: u64, detail: impl Into<String>) -> RecordError {
        RecordError::Corrupt {
            path: self.path.to_path_buf(),
            offset,
            detail: detail.into(),
        }
    }

    fn io(&self, source: std::io::Error) -> RecordError {
        RecordError::Io {
            path: self.path.to_path_buf(),
            source,
        }
    }

    /// Every message index the last chunk needs must have been read.
    fn close_pending(&mut self) -> Result<(), RecordError> {
        if let Some((chunk, need)) = self.pending.take() {
            if let Some(ch) = need.keys().next() {
                return Err(self.corrupt(
                    chunk,
                    format!(
                        "the chunk at byte offset {chunk} has no message index for its \
                         messages on channel {ch}"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Handles one top-level record at `self.offset`.
    fn record(
        &mut self,
        opcode: u8,
        body: &[u8],
        on: &mut dyn FnMut(Item<'_>, At) -> Result<(), RecordError>,
    ) -> Result<(), RecordError> {
        let at = At {
            offset: self.offset,
            chunk: None,
        };
        let bad = |s: &Self, d: String| s.corrupt(at.offset, d);
        if !self.header && opcode != op::HEADER {
            return Err(bad(
                self,
                format!(
                    "the first record is a {} record, not a header",
                    op_name(opcode)
                ),
            ));
        }
        if opcode != op::MESSAGE_INDEX {
            self.close_pending()?;
        }
        match (self.section, opcode) {
            (Section::Data, op::HEADER) => {
                if self.header {
                    return Err(bad(self, "a second header record".into()));
                }
                self.header = true;
                let Record::Header(h) =
                    parse(opcode, body).map_err(|d| bad(self, d.to_string()))?
                else {
                    return Err(bad(self, "header record does not parse".into()));
                };
                on(
                    Item::Header {
                        profile: &h.profile,
                        library: &h.library,
                    },
                    at,
                )
            }
            (Section::Data, op::METADATA) => {
                let Record::Metadata(m) =
                    parse(opcode, body).map_err(|d| bad(self, d.to_string()))?
                else {
                    return Err(bad(self, "metadata record does not parse".into()));
                };
                on(
                    Item::Metadata {
                        name: &m.name,
                        map: &m.metadata,
                    },
                    at,
                )
            }
            (Section::Data, op::SCHEMA | op::CHANNEL) => {
                let rec = parse(opcode, body).map_err(|d| bad(self, d.to_string()))?;
                self.register(rec).map_err(|d| bad(self, d.to_string()))
            }
            (Section::Data, op::CHUNK) => self.chunk(body, on),
            (Section::Data, op::MESSAGE_INDEX) => {
                let Record::MessageIndex(ix) =
                    parse(opcode, body).map_err(|d| bad(self, d.to_string()))?
                else {
                    return Err(bad(self, "message index does not parse".into()));
                };
                let Some((chunk, need)) = self.pending.as_mut() else {
                    return Err(bad(
                        self,
                        format!(
                            "message index of channel {} follows no chunk",
                            ix.channel_id
                        ),
                    ));
                };
                let chunk = *chunk;
                let mut got: Vec<(u64, u64)> =
                    ix.records.iter().map(|e| (e.log_time, e.offset)).collect();
                got.sort_unstable();
                match need.remove(&ix.channel_id) {
                    Some(want) if want == got => Ok(()),
                    _ => Err(bad(
                        self,
                        format!(
                            "message index of channel {} does not match the messages of the \
                             chunk at byte offset {chunk}",
                            ix.channel_id
                        ),
                    )),
                }
            }
            (Section::Data, op::DATA_END) => {
                self.section = Section::Summary;
                Ok(())
            }
            (
                Section::Summary,
                op::SCHEMA
                | op::CHANNEL
                | op::CHUNK_INDEX
                | op::ATTACHMENT_INDEX
                | op::METADATA_INDEX
                | op::STATISTICS
                | op::SUMMARY_OFFSET,
            ) => Ok(()), // covered by the summary CRC, checked at the footer
            (Section::Summary, op::FOOTER) => {
                self.section = Section::EndMagic;
                Ok(())
            }
            (section, opcode) => Err(bad(
                self,
                format!(
                    "unexpected {} record in the {} section",
                    op_name(opcode),
                    match section {
                        Section::Data => "data",
                        Section::Summary => "summary",
                        Section::EndMagic => "end",
                    }
                ),
            )),
        }
    }

    fn register(&mut self, rec: Record<'_>) -> Result<(), BadRecord> {
        match rec {
            Record::Schema { header, .. } => {
                if header.id == 0 {
                    return Err(BadRecord::SchemaIdZero);
                }
                self.schemas.insert(header.id, header.name);
                Ok(())
            }
            Record::Channel(c) => {
                let schema = match c.schema_id {
                    0 => String::new(),
                    id => self
                        .schemas
                        .get(&id)
                        .cloned()
                        .ok_or(BadRecord::UnknownSchema {
                            channel: c.id,
                            schema: id,
                        })?,
                };
                self.channels.insert(
                    c.id,
                    Channel {
                        topic: c.topic,
                        schema,
                        encoding: c.message_encoding,
                    },
                );
                Ok(())
            }
            _ => Err(BadRecord::NotSchemaOrChannel),
        }
    }

    /// Decompresses one chunk (whole record body `body` at `self.offset`), validates its CRC
    /// and header, and hands its messages to `on`.
    fn chunk(
        &mut self,
        body: &[u8],
        on: &mut dyn FnMut(Item<'_>, At) -> Result<(), RecordError>,
    ) -> Result<(), RecordError> {
        let offset = self.offset;
        let ordinal = self.chunks;
        self.chunks += 1;
        let bad = |s: &Self, d: String| s.corrupt(offset, format!("chunk {ordinal}: {d}"));
        let Record::Chunk { header, data } =
            parse(op::CHUNK, body).map_err(|d| bad(self, d.to_string()))?
        else {
            return Err(bad(self, "does not parse".into()));
        };
        let header_len = 40 + header.compression.len() as u64;
        if header_len + header.compressed_size != body.len() as u64 {
            return Err(bad(
                self,
                format!(
                    "record length {} does not match its {header_len}-byte header and {} \
                     compressed bytes",
                    body.len(),
                    header.compressed_size
                ),
            ));
        }
        if header.uncompressed_size > MAX_RECORD as u64 {
            return Err(bad(
                self,
                format!(
                    "declares {} uncompressed bytes, more than the {} MiB limit",
                    header.uncompressed_size,
                    MAX_RECORD >> 20
                ),
            ));
        }
        if header.uncompressed_crc == 0 {
            return Err(bad(
                self,
                "has no CRC (mjskill writes one for every chunk)".into(),
            ));
        }
        if !matches!(header.compression.as_str(), "zstd" | "") {
            return Err(bad(
                self,
                format!("unknown compression {:?}", header.compression),
            ));
        }
        drop(data);
        let mut inner = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_prevalidate_chunk_crcs(true)
                .with_record_length_limit(MAX_RECORD),
        );
        let mut framed = Some(body);
        let mut inner_off = 0u64;
        let mut need = IndexEntries::new();
        let mut times: Option<(u64, u64)> = None;
        while let Some(ev) = inner.next_event() {
            match ev.map_err(|e| bad(self, mcap_detail(&e)))? {
                LinearReadEvent::ReadRequest(_) => match framed.take() {
                    Some(b) => {
                        let n = PREFIX as usize + b.len();
                        let buf = inner.insert(n);
                        buf[0] = op::CHUNK;
                        buf[1..9].copy_from_slice(&(b.len() as u64).to_le_bytes());
                        buf[9..].copy_from_slice(b);
                        inner.notify_read(n);
                    }
                    None => inner.notify_read(0),
                },
                LinearReadEvent::Record { opcode, data } => {
                    let here = inner_off;
                    inner_off += PREFIX + data.len() as u64;
                    let rec = parse(opcode, data).map_err(|d| {
                        bad(self, format!("record at byte {here} of its data: {d}"))
                    })?;
                    match rec {
                        Record::Message { header: h, data } => {
                            let Some(c) = self.channels.get(&h.channel_id) else {
                                return Err(bad(
                                    self,
                                    format!("message on unknown channel {}", h.channel_id),
                                ));
                            };
                            need.entry(h.channel_id)
                                .or_default()
                                .push((h.log_time, here));
                            times = Some(match times {
                                None => (h.log_time, h.log_time),
                                Some((a, b)) => (a.min(h.log_time), b.max(h.log_time)),
                            });
                            on(
                                Item::Message {
                                    topic: &c.topic,
                                    schema: &c.schema,
                                    encoding: &c.encoding,
                                    log_time: h.log_time,
                                    data: &data,
                                },
                                At {
                                    offset,
                                    chunk: Some((ordinal, offset)),
                                },
                            )?;
                        }
                        rec @ (Record::Schema { .. } | Record::Channel(_)) => {
                            self.register(rec).map_err(|d| bad(self, d.to_string()))?
                        }
                        other => {
                            return Err(bad(
                                self,
                                format!("unexpected {} record", op_name(other.opcode())),
                            ))
                        }
                    }
                }
            }
        }
        let (start, end) = times.unwrap_or((0, 0));
        if (header.message_start_time, header.message_end_time) != (start, end) {
            return Err(bad(
                self,
                format!(
                    "header time range {}..{} differs from its messages' {start}..{end}",
                    header.message_start_time, header.message_end_time
                ),
            ));
        }
        for v in need.values_mut() {
            v.sort_unstable();
        }
        self.pending = Some((offset, need));
        Ok(())
    }

    /// The reader ran out of bytes at `self.offset`: a cut (Ok) or damage (Err).
    fn tail(&self, file: &mut File, len: u64, closed: bool) -> Result<End, RecordError> {
        let at = self.offset;
        if closed {
            return Err(self.corrupt(
                at,
                format!(
                    "the record at byte offset {at} runs past the end of the file, which was \
                     closed properly (it ends with the end magic)"
                ),
            ));
        }
        let avail = len.saturating_sub(at);
        let mut tail = vec![0u8; avail.min(PREFIX + 4096) as usize];
        file.seek(SeekFrom::Start(at)).map_err(|e| self.io(e))?;
        file.read_exact(&mut tail).map_err(|e| self.io(e))?;
        let cut = |what: String| {
            Ok(End {
                complete: false,
                truncated: Some((len, what)),
            })
        };
        if self.section == Section::EndMagic {
            return if mcap::MAGIC.starts_with(&tail) {
                cut(format!("the file ends inside its end magic at byte {len}"))
            } else {
                Err(self.corrupt(at, "bad end magic"))
            };
        }
        if avail == 0 {
            return cut(match self.last {
                Some((off, opcode)) => format!(
                    "the file ends at byte {len}, after the {} record at byte offset {off}",
                    op_name(opcode)
                ),
                None => format!("the file ends at byte {len}, after the magic"),
            });
        }
        if tail.len() < PREFIX as usize {
            return cut(format!(
                "the file ends at byte {len}, inside the record header at byte offset {at}"
            ));
        }
        let opcode = tail[0];
        let rlen = u64::from_le_bytes(tail[1..9].try_into().unwrap_or([0; 8]));
        let body = &tail[9..];
        let u32_at = |i: usize| -> Option<u64> {
            body.get(i..i + 4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64)
        };
        let u64_at = |i: usize| -> Option<u64> {
            body.get(i..i + 8)
                .and_then(|b| b.try_into().ok())
                .map(u64::from_le_bytes)
        };
        let damaged = |d: String| {
            Err(self.corrupt(
                at,
                format!(
                    "the last record (at byte offset {at}, {}) is not the beginning of a \
                     record cut short: {d}",
                    op_name(opcode)
                ),
            ))
        };
        let expected = match (self.section, opcode) {
            (Section::Data, op::CHUNK | op::MESSAGE_INDEX | op::METADATA | op::DATA_END) => true,
            (Section::Data, op::HEADER) => !self.header,
            (
                Section::Summary,
                op::SCHEMA
                | op::CHANNEL
                | op::CHUNK_INDEX
                | op::ATTACHMENT_INDEX
                | op::METADATA_INDEX
                | op::STATISTICS
                | op::SUMMARY_OFFSET
                | op::FOOTER,
            ) => true,
            _ => false,
        };
        if !expected {
            return damaged("no such record can stand here".into());
        }
        if rlen <= avail - PREFIX {
            return damaged(format!("it is complete ({rlen} bytes) yet does not parse"));
        }
        match opcode {
            op::DATA_END if rlen != 4 => return damaged(format!("length {rlen}, not 4")),
            op::FOOTER if rlen != 20 => return damaged(format!("length {rlen}, not 20")),
            op::CHUNK => {
                if let Some(clen) = u32_at(28) {
                    if 40 + clen > rlen {
                        return damaged(format!("compression name of {clen} bytes"));
                    }
                    if let Some(name) = body.get(32..32 + clen as usize) {
                        if name != b"zstd" && !name.is_empty() {
                            return damaged("unknown compression".into());
                        }
                    }
                    if let Some(csize) = u64_at(32 + clen as usize) {
                        if Some(rlen) != (40 + clen).checked_add(csize) {
                            return damaged(format!(
                                "length {rlen} does not match its header and {csize} \
                                 compressed bytes"
                            ));
                        }
                    }
                }
                if let Some(usize_) = u64_at(16) {
                    if usize_ > MAX_RECORD as u64 {
                        return damaged(format!("{usize_} uncompressed bytes"));
                    }
                }
                if u32_at(24) == Some(0) {
                    return damaged("no CRC".into());
                }
            }
            op::MESSAGE_INDEX => {
                if let Some(n) = u32_at(2) {
                    if rlen != 6 + n || n % 16 != 0 {
                        return damaged(format!("length {rlen} for {n} bytes of entries"));
                    }
                }
            }
            op::METADATA => {
                if let Some(n) = u32_at(0) {
                    if 8 + n > rlen {
                        return damaged(format!("name of {n} bytes"));
                    }
                    if let Some(m) = u32_at(4 + n as usize) {
                        if rlen != 8 + n + m {
                            return damaged(format!("length {rlen} for a {m}-byte map"));
                        }
                    }
                }
            }
            _ => {}
        }
        if rlen > MAX_RECORD as u64 {
            return damaged(format!("{rlen} bytes"));
        }
        cut(format!(
            "the file ends at byte {len}, inside the {} record at byte offset {at} ({} of its \
             {} bytes are present)",
            op_name(opcode),
            avail,
            PREFIX + rlen
        ))
    }
}

/// Whether the file ends with the end magic, i.e. it was closed properly (a cut file ends
/// inside or after a data record; that its last 8 bytes equal the magic by chance is
/// negligible).
fn closed(file: &mut File, len: u64) -> std::io::Result<bool> {
    if len < 16 {
        return Ok(false);
    }
    let mut b = [0u8; 8];
    file.seek(SeekFrom::Start(len - 8))?;
    file.read_exact(&mut b)?;
    Ok(b == mcap::MAGIC)
}

/// Reads the MCAP file at `path` from start to end, handing every header, metadata record and
/// message to `on` with where it lies. Returns how the file ended (complete, or cut short and
/// where); damage is an [`RecordError::Corrupt`] naming the byte offset (and the chunk).
/// Errors returned by `on` stop the scan and are returned as they are.
pub(crate) fn scan(
    path: &Path,
    on: &mut dyn FnMut(Item<'_>, At) -> Result<(), RecordError>,
) -> Result<End, RecordError> {
    let io = |source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    };
    let not = |reason: &str| RecordError::NotRecording {
        path: PathBuf::from(path),
        reason: reason.to_string(),
    };
    let mut file = File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if len == 0 {
        return Err(not("the file is empty"));
    }
    let mut magic = [0u8; 8];
    let n = (len as usize).min(8);
    file.read_exact(&mut magic[..n]).map_err(io)?;
    if !mcap::MAGIC.starts_with(&magic[..n]) {
        return Err(not("not an MCAP file (bad magic)"));
    }
    if n < 8 {
        return Err(RecordError::Truncated {
            path: path.to_path_buf(),
            offset: len,
            detail: format!("the file ends at byte {len}, inside the MCAP magic"),
        });
    }
    let closed = closed(&mut file, len).map_err(io)?;
    file.seek(SeekFrom::Start(0)).map_err(io)?;
    let mut top = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(MAX_RECORD)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_check_finishes_after_end_magic(true),
    );
    let mut s = Scan {
        path,
        offset: 8,
        section: Section::Data,
        header: false,
        chunks: 0,
        schemas: HashMap::new(),
        channels: HashMap::new(),
        pending: None,
        last: None,
    };
    while let Some(ev) = top.next_event() {
        match ev {
            Ok(LinearReadEvent::ReadRequest(n)) => {
                let buf = top.insert(n.clamp(1, PIECE));
                let k = read_some(&mut file, buf).map_err(io)?;
                top.notify_read(k);
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                let size = PREFIX + data.len() as u64;
                s.record(opcode, data, on)?;
                s.last = Some((s.offset, opcode));
                s.offset += size;
            }
            Err(McapError::UnexpectedEof) => return s.tail(&mut file, len, closed),
            Err(e) => {
                let what = match s.section {
                    Section::EndMagic => "after the footer".to_string(),
                    _ => format!("in the record at byte offset {}", s.offset),
                };
                return Err(s.corrupt(s.offset, format!("{what}: {}", mcap_detail(&e))));
            }
        }
    }
    Ok(End {
        complete: s.section == Section::EndMagic,
        truncated: None,
    })
}
