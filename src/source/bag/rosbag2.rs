//! rosbag2: the `metadata.yaml` of a bag directory, and its sqlite3 storage.
//!
//! A rosbag2 bag is a directory: `metadata.yaml` (storage identifier `sqlite3` or `mcap`, the
//! files in order, the topics with their types and serialization format, the compression
//! format and mode) and one or more storage files. [`Metadata::parse`] reads the yaml;
//! [`SqliteReader`] reads one `.db3` file (also a bare `.db3` without its yaml: its `topics`
//! table names the types). MCAP files go through [`super::mcap_in`].
//!
//! Bags whose yaml or `topics` table leaves `serialization_format` or `storage_identifier`
//! empty (two of nebula's test bags do) are read as CDR / sqlite3 — the only values those
//! fields had before they were recorded.
//!
//! # sqlite3 reading
//! Messages come `ORDER BY timestamp, id` (as `ros2 bag play` plays them) through the
//! `timestamp_idx` index rosbag2 creates; a file without that index is read in `id`
//! (insertion) order rather than sorted. The query selects no message bytes (rowids, topics
//! and times, in batches of rows, resumed after the last row read); each message is read when
//! it is asked for, by its rowid, through one incremental blob handle kept open beside the
//! connection, straight into the one reused buffer the decoder reads, after its length is
//! checked (one larger than [`MAX_MESSAGE_BYTES`] is counted and
//! skipped). One message's bytes are held at a time. SQLite's own cache
//! is its default (about 2 MiB). The file is read through a memory map (its first 2 GiB, the
//! most SQLite maps), dropped and made afresh every 16 MiB (`REMAP_BYTES`) of messages so that the
//! pages it touched do not pile up in the process's resident memory. The file is opened
//! read-only and `immutable` (no journal, no lock files: bags on read-only media open).

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};

use rusqlite::{Connection as Db, OpenFlags};
use yaml_rust2::{Yaml, YamlLoader};

use super::messages::Encoding;
use super::{BagError, Connection, RawMessage, MAX_CONNECTIONS, MAX_MESSAGE_BYTES, MAX_NAME_BYTES};

/// Rows fetched per query at most (their topics, times and rowids; the bytes are read one
/// message at a time).
const BATCH_ROWS: usize = 256;
/// `PRAGMA mmap_size`: the whole file (SQLite clamps it to its build's maximum).
const MMAP_SIZE: i64 = 1 << 40;
/// Message bytes read between two remappings of the file: the pages of the map touched since
/// the last one count in the process's resident memory until it is dropped, so this bounds
/// what a bag of any size adds to it. (A remap closes and later reopens the blob handle.)
const REMAP_BYTES: u64 = 16 << 20;

/// Storage plugin of a rosbag2 bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// sqlite3 (`.db3`).
    Sqlite3,
    /// MCAP (`.mcap`).
    Mcap,
}

/// How a rosbag2 bag is compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// Not compressed.
    None,
    /// Each storage file is one zstd stream (`.db3.zstd`, `.mcap.zstd`).
    File,
    /// Each message's bytes are one zstd frame.
    Message,
}

/// What `metadata.yaml` says.
#[derive(Debug, Clone)]
pub struct Metadata {
    /// Storage plugin (`sqlite3` when empty).
    pub storage: Storage,
    /// Storage files, relative to the bag directory, in order.
    pub files: Vec<String>,
    /// Compression.
    pub compression: Compression,
    /// Topics: name, type, serialization format (`cdr` when empty).
    pub topics: Vec<(String, String, String)>,
}

fn str_of(y: &Yaml) -> Option<&str> {
    y.as_str()
}

impl Metadata {
    /// Parses a `metadata.yaml`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let docs = YamlLoader::load_from_str(text).map_err(|e| e.to_string())?;
        let root = docs
            .first()
            .map(|d| &d["rosbag2_bagfile_information"])
            .filter(|y| !y.is_badvalue())
            .ok_or("no rosbag2_bagfile_information")?;
        let storage = match str_of(&root["storage_identifier"]).unwrap_or("") {
            "" | "sqlite3" => Storage::Sqlite3,
            "mcap" => Storage::Mcap,
            other => {
                return Err(format!(
                    "storage_identifier {other:?}: expected sqlite3 or mcap"
                ))
            }
        };
        let compression = match (
            str_of(&root["compression_format"]).unwrap_or(""),
            str_of(&root["compression_mode"])
                .unwrap_or("")
                .to_ascii_uppercase()
                .as_str(),
        ) {
            (_, "" | "NONE") => Compression::None,
            ("zstd", "FILE") => Compression::File,
            ("zstd", "MESSAGE") => Compression::Message,
            (f, m) => {
                return Err(format!(
                    "compression {f:?} mode {m:?}: expected zstd with FILE or MESSAGE"
                ))
            }
        };
        let mut files: Vec<String> = root["relative_file_paths"]
            .as_vec()
            .map(|v| {
                v.iter()
                    .filter_map(|f| str_of(f).map(str::to_string))
                    .collect()
            })
            .unwrap_or_default();
        if files.is_empty() {
            files = root["files"]
                .as_vec()
                .map(|v| {
                    v.iter()
                        .filter_map(|f| str_of(&f["path"]).map(str::to_string))
                        .collect()
                })
                .unwrap_or_default();
        }
        let topics = root["topics_with_message_count"]
            .as_vec()
            .map(|v| {
                v.iter()
                    .filter_map(|t| {
                        let m = &t["topic_metadata"];
                        Some((
                            str_of(&m["name"])?.to_string(),
                            str_of(&m["type"]).unwrap_or("").to_string(),
                            str_of(&m["serialization_format"]).unwrap_or("").to_string(),
                        ))
                    })
                    .collect()
            })
            .unwrap_or_default();
        Ok(Self {
            storage,
            files,
            compression,
            topics,
        })
    }
}

/// The encoding of a rosbag2 serialization format (empty: CDR).
pub fn encoding_of(format: &str) -> Option<Encoding> {
    match format {
        "" | "cdr" => Some(Encoding::Cdr),
        "ros1" => Some(Encoding::Ros1),
        _ => None,
    }
}

/// The one incremental blob handle through which every message is read, kept open beside the
/// connection it borrows (reopened row to row; opening one compiles a statement).
type BlobSlot<'a> = Option<rusqlite::blob::Blob<'a>>;

self_cell::self_cell!(
    /// A connection and its blob handle.
    struct DbBlob {
        owner: Db,
        #[covariant]
        dependent: BlobSlot,
    }
);

/// Messages of one sqlite3 storage file. See the [module documentation](self).
pub struct SqliteReader {
    path: PathBuf,
    db: DbBlob,
    topics: HashMap<i64, Connection>,
    order: Vec<i64>,
    by_timestamp: bool,
    /// (timestamp, id) of the last row fetched.
    last: Option<(i64, i64)>,
    /// Rows fetched, their bytes not read yet: topic, timestamp, rowid.
    queue: VecDeque<(i64, i64, i64)>,
    /// The message last returned: a buffer that keeps its largest length (growing it zeroes
    /// the new bytes, so it is never shrunk) and the message's length in it.
    current: (Vec<u8>, usize),
    done: bool,
    /// Message bytes read so far (progress).
    pub(crate) bytes: u64,
    /// `bytes` when the file was last mapped afresh.
    mapped_at: u64,
    /// Messages larger than [`MAX_MESSAGE_BYTES`], skipped.
    pub(crate) oversized: u64,
}

fn sql_err(path: &Path, e: rusqlite::Error) -> BagError {
    BagError::Sqlite {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// A `file:` URI for `path`, read-only and immutable.
fn uri(path: &Path) -> String {
    let mut s = String::from("file:");
    for b in path.to_string_lossy().bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'/' | b'.' | b'-' | b'_' | b'~' => {
                s.push(char::from(b))
            }
            _ => s.push_str(&format!("%{b:02X}")),
        }
    }
    s.push_str("?mode=ro&immutable=1");
    s
}

impl SqliteReader {
    /// Opens a `.db3` and reads its `topics` table.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let flags = OpenFlags::SQLITE_OPEN_READ_ONLY
            | OpenFlags::SQLITE_OPEN_URI
            | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let db = Db::open_with_flags(uri(path), flags).map_err(|e| sql_err(path, e))?;
        let mut topics = HashMap::new();
        let mut order = Vec::new();
        {
            let mut st = db
                .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
                .map_err(|e| sql_err(path, e))?;
            let rows = st
                .query_map([], |r| {
                    Ok((
                        r.get::<_, i64>(0)?,
                        r.get::<_, String>(1)?,
                        r.get::<_, String>(2)?,
                        r.get::<_, Option<String>>(3)?.unwrap_or_default(),
                    ))
                })
                .map_err(|e| sql_err(path, e))?;
            for row in rows {
                let (id, name, ty, fmt) = row.map_err(|e| sql_err(path, e))?;
                let too_many = order.len() >= MAX_CONNECTIONS;
                if too_many || name.len().max(ty.len()) > MAX_NAME_BYTES {
                    return Err(BagError::Sqlite {
                        path: path.to_path_buf(),
                        reason: if too_many {
                            format!("more than {MAX_CONNECTIONS} topics")
                        } else {
                            format!("topic {id}: name or type longer than {MAX_NAME_BYTES} bytes")
                        },
                    });
                }
                order.push(id);
                topics.insert(
                    id,
                    Connection {
                        topic: name,
                        type_name: ty,
                        encoding: encoding_of(&fmt),
                    },
                );
            }
        }
        // Memory-mapped reads where SQLite allows them (its first 2 GiB: the build's maximum):
        // a message's pages then cost page faults (the kernel maps 16 at a time) instead of one
        // `pread` per 4 KiB page, which made an Ouster bag 27 % slower than its pcap. Failing
        // to map is not an error: the reads fall back to `pread`.
        let _ = db.pragma_update(None, "mmap_size", MMAP_SIZE);
        let by_timestamp: bool = db
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'index' AND tbl_name = 'messages' \
                 AND sql LIKE '%timestamp%'",
                [],
                |r| r.get::<_, i64>(0),
            )
            .map_err(|e| sql_err(path, e))?
            > 0;
        Ok(Self {
            path: path.to_path_buf(),
            db: DbBlob::new(db, |_| None),
            topics,
            order,
            by_timestamp,
            last: None,
            queue: VecDeque::new(),
            current: (Vec::new(), 0),
            done: false,
            bytes: 0,
            mapped_at: 0,
            oversized: 0,
        })
    }

    /// The topic `id`.
    pub fn connection(&self, id: u64) -> Option<&Connection> {
        i64::try_from(id).ok().and_then(|i| self.topics.get(&i))
    }

    /// How many topics [`Self::connections_from`] lists (from 0).
    pub fn connection_count(&self) -> usize {
        self.order.len()
    }

    /// The topics from the `first`-th on, in id order.
    pub fn connections_from(&self, first: usize) -> Vec<(u64, Connection)> {
        self.order
            .get(first..)
            .unwrap_or_default()
            .iter()
            .filter_map(|id| Some((u64::try_from(*id).ok()?, self.topics.get(id)?.clone())))
            .collect()
    }

    /// The next rows, in order: their topics, times and rowids (no message bytes).
    fn fetch(&mut self) -> Result<(), BagError> {
        let sql = match (self.by_timestamp, self.last.is_some()) {
            (true, false) => {
                "SELECT id, topic_id, timestamp, rowid FROM messages \
                 ORDER BY timestamp, id LIMIT ?3"
            }
            (true, true) => {
                "SELECT id, topic_id, timestamp, rowid FROM messages \
                 WHERE timestamp > ?1 OR (timestamp = ?1 AND id > ?2) \
                 ORDER BY timestamp, id LIMIT ?3"
            }
            (false, false) => {
                "SELECT id, topic_id, timestamp, rowid FROM messages ORDER BY id LIMIT ?3"
            }
            (false, true) => {
                "SELECT id, topic_id, timestamp, rowid FROM messages \
                 WHERE id > ?2 ORDER BY id LIMIT ?3"
            }
        };
        let (ts, id) = self.last.unwrap_or((i64::MIN, i64::MIN));
        let path = &self.path;
        let mut st = (self.db.borrow_owner())
            .prepare_cached(sql)
            .map_err(|e| sql_err(path, e))?;
        let mut rows = st
            .query(rusqlite::params![ts, id, BATCH_ROWS as i64])
            .map_err(|e| sql_err(path, e))?;
        let mut n = 0usize;
        while let Some(row) = rows.next().map_err(|e| sql_err(path, e))? {
            n += 1;
            let id: i64 = row.get(0).map_err(|e| sql_err(path, e))?;
            let topic: i64 = row.get(1).map_err(|e| sql_err(path, e))?;
            let ts: i64 = row.get(2).map_err(|e| sql_err(path, e))?;
            let rowid: i64 = row.get(3).map_err(|e| sql_err(path, e))?;
            self.last = Some((ts, id));
            self.queue.push_back((topic, ts, rowid));
        }
        if n == 0 {
            self.done = true;
        }
        Ok(())
    }

    /// Reads the bytes of row `rowid` into `current`, unless larger than [`MAX_MESSAGE_BYTES`]
    /// (then `Ok(false)`). The bytes go from SQLite's pages straight into the buffer the decoder
    /// reads next, while they are in cache: selecting `data` would have SQLite assemble each
    /// blob in a buffer of its own first, and reading a batch ahead of the decoder would have
    /// them leave the core's cache before it reads them.
    fn read_row(&mut self, rowid: i64) -> Result<bool, BagError> {
        if self.bytes - self.mapped_at >= REMAP_BYTES {
            // With the blob handle closed no statement or handle holds a page (the row query
            // is done): the map can go, and with it the resident pages it had gathered. Both
            // settings are hints.
            self.db.with_dependent_mut(|_, blob| *blob = None);
            let db = self.db.borrow_owner();
            let _ = db.pragma_update(None, "mmap_size", 0);
            let _ = db.pragma_update(None, "mmap_size", MMAP_SIZE);
            self.mapped_at = self.bytes;
        }
        let (path, current) = (&self.path, &mut self.current);
        self.db.with_dependent_mut(|db, blob| {
            let opened = match blob.as_mut() {
                Some(b) => b.reopen(rowid),
                None => db
                    .blob_open(rusqlite::MAIN_DB, "messages", "data", rowid, true)
                    .map(|b| *blob = Some(b)),
            };
            match (opened, blob.as_ref()) {
                (Ok(()), Some(b)) => {
                    let len = usize::try_from(b.size()).unwrap_or(usize::MAX);
                    if len > MAX_MESSAGE_BYTES {
                        return Ok(false);
                    }
                    if current.0.len() < len {
                        current.0.resize(len, 0);
                    }
                    b.read_at_exact(&mut current.0[..len], 0)
                        .map_err(|e| sql_err(path, e))?;
                    current.1 = len;
                    Ok(true)
                }
                // A NULL or numeric `data` (not a blob or text): an empty message, which the
                // packet parser counts. A failed reopen leaves the handle unusable.
                (Err(rusqlite::Error::SqliteFailure(e, _)), _)
                    if e.code == rusqlite::ErrorCode::Unknown =>
                {
                    *blob = None;
                    current.1 = 0;
                    Ok(true)
                }
                (Err(e), _) => Err(sql_err(path, e)),
                (Ok(()), None) => {
                    current.1 = 0;
                    Ok(true)
                }
            }
        })
    }

    /// The next message; its bytes are [`Self::message`].
    pub fn next_message(&mut self) -> Result<Option<RawMessage>, BagError> {
        loop {
            while self.queue.is_empty() {
                if self.done {
                    return Ok(None);
                }
                if let Err(e) = self.fetch() {
                    self.done = true;
                    return Err(e);
                }
            }
            let Some((topic, ts, rowid)) = self.queue.pop_front() else {
                return Ok(None);
            };
            match self.read_row(rowid) {
                Ok(true) => {}
                Ok(false) => {
                    self.oversized += 1;
                    continue;
                }
                Err(e) => {
                    self.done = true;
                    self.queue.clear();
                    return Err(e);
                }
            }
            self.bytes += self.current.1 as u64;
            return Ok(Some(RawMessage {
                conn: u64::try_from(topic).unwrap_or(u64::MAX),
                time_ns: ts,
            }));
        }
    }

    /// The bytes of the message last returned by [`Self::next_message`].
    pub fn message(&self) -> &[u8] {
        self.current.0.get(..self.current.1).unwrap_or(&[])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nebula_style_metadata_with_empty_fields() {
        let y = "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: \"\"\n  \
                 topics_with_message_count:\n    - topic_metadata:\n        name: /velodyne_packets\n        \
                 type: velodyne_msgs/msg/VelodyneScan\n        serialization_format: \"\"\n      \
                 message_count: 4\n  compression_format: \"\"\n  compression_mode: \"\"\n  \
                 relative_file_paths:\n    - a_0.db3\n    - a_1.db3\n";
        let m = Metadata::parse(y).unwrap();
        assert_eq!(m.storage, Storage::Sqlite3);
        assert_eq!(m.compression, Compression::None);
        assert_eq!(m.files, ["a_0.db3", "a_1.db3"]);
        assert_eq!(m.topics[0].1, "velodyne_msgs/msg/VelodyneScan");
        assert_eq!(encoding_of(&m.topics[0].2), Some(Encoding::Cdr));
    }

    #[test]
    fn uri_escapes_what_sqlite_would_read_as_query() {
        assert_eq!(
            uri(Path::new("/a b/c?d#e.db3")),
            "file:/a%20b/c%3Fd%23e.db3?mode=ro&immutable=1"
        );
    }
}
