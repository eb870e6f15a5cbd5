//! A file read on a thread of its own, a few blocks ahead of the parser.
//!
//! Reading a capture from the page cache is a kernel copy that costs about a third of the
//! decoding thread's time on an Ouster capture (`perf`: `_copy_to_iter` and the page-cache
//! look-ups); on a machine with a spare core it can run beside the decoding instead of before
//! it. The parser sees a plain [`Read`]: the bytes in order, then the end or the first error.
//!
//! Memory is bounded: the blocks in flight (the channel's depth) plus one being filled and
//! one being read. Buffers go back to the reading thread instead of being freed, so a long
//! capture allocates [`BLOCK`]-sized buffers only at the start. Dropping the reader stops the
//! thread at its next block.

use std::io::{self, Read};
use std::ops::Range;
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError};
use std::thread;

/// Bytes per block: large enough that a channel hand-over costs nothing beside the copy.
pub const BLOCK: usize = 1 << 20;
/// Blocks waiting for the parser at most.
pub const DEPTH: usize = 4;

/// A [`Read`] whose bytes are read from `R` by a thread of its own.
pub struct ReadAhead {
    rx: Receiver<io::Result<Vec<u8>>>,
    /// Empty buffers back to the reading thread.
    back: SyncSender<Vec<u8>>,
    cur: Vec<u8>,
    pos: usize,
    /// The end, or an error already returned: nothing more is read.
    done: bool,
}

impl ReadAhead {
    /// Starts reading `inner` on a new thread named `name`. Fails only when the thread cannot
    /// be started (`inner` is then dropped: the caller opens its file again and reads it
    /// itself).
    pub fn spawn<R: Read + Send + 'static>(inner: R, name: &str) -> io::Result<Self> {
        let (tx, rx) = mpsc::sync_channel(DEPTH);
        // Room for every buffer that can exist, so handing one back never blocks the parser.
        let (back, back_rx) = mpsc::sync_channel(DEPTH + 2);
        thread::Builder::new()
            .name(name.to_string())
            .spawn(move || fill_blocks(inner, &tx, &back_rx))?;
        Ok(Self {
            rx,
            back,
            cur: Vec::new(),
            pos: 0,
            done: false,
        })
    }
}

/// The reading thread: blocks of up to [`BLOCK`] bytes, in order, until the end, an error, or
/// the parser gone.
fn fill_blocks<R: Read>(
    mut inner: R,
    tx: &SyncSender<io::Result<Vec<u8>>>,
    back: &Receiver<Vec<u8>>,
) {
    loop {
        let mut buf = match back.try_recv() {
            Ok(b) => b,
            Err(TryRecvError::Empty) => Vec::new(),
            Err(TryRecvError::Disconnected) => return,
        };
        // A buffer handed back is whole (only the last, short block is cut, and the thread
        // has stopped by then): zeroing it again would cost a memset per block.
        if buf.len() != BLOCK {
            buf.resize(BLOCK, 0);
        }
        let mut filled = 0;
        while filled < BLOCK {
            match inner.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    buf.truncate(filled);
                    if filled > 0 && tx.send(Ok(buf)).is_err() {
                        return;
                    }
                    let _ = tx.send(Err(e));
                    return;
                }
            }
        }
        buf.truncate(filled);
        if filled == 0 || tx.send(Ok(buf)).is_err() {
            return; // the end (dropping `tx` tells the parser), or the parser gone
        }
        if filled < BLOCK {
            return; // a short block is the last
        }
    }
}

impl ReadAhead {
    /// Makes the next block current once the current one is used up; false at the end (or
    /// after an error, which is returned once).
    fn ensure_block(&mut self) -> io::Result<bool> {
        while self.pos >= self.cur.len() {
            if self.done {
                return Ok(false);
            }
            match self.rx.recv() {
                Ok(Ok(next)) => {
                    let used = std::mem::replace(&mut self.cur, next);
                    self.pos = 0;
                    if used.capacity() > 0 {
                        // Full only if the thread has stopped: the buffer is then freed here.
                        let _ = self.back.try_send(used);
                    }
                }
                Ok(Err(e)) => {
                    self.done = true;
                    return Err(e);
                }
                Err(_) => {
                    self.done = true;
                    return Ok(false);
                }
            }
        }
        Ok(true)
    }

    /// The next `n` bytes where they already lie, without a copy, when the current block holds
    /// them all: their place in [`Self::block`], consumed. `None` when they run past the block
    /// (or the file): read them with [`Read::read`] instead, which consumes nothing more than
    /// it gives. The range stays valid until the next call that takes `&mut self`.
    pub fn lend(&mut self, n: usize) -> io::Result<Option<Range<usize>>> {
        if !self.ensure_block()? {
            return Ok(None);
        }
        let start = self.pos;
        match start.checked_add(n) {
            Some(end) if end <= self.cur.len() => {
                self.pos = end;
                Ok(Some(start..end))
            }
            _ => Ok(None),
        }
    }

    /// The current block (ranges from [`Self::lend`] index it).
    pub fn block(&self) -> &[u8] {
        &self.cur
    }
}

impl Read for ReadAhead {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if out.is_empty() || !self.ensure_block()? {
            return Ok(0);
        }
        let avail = self.cur.get(self.pos..).unwrap_or(&[]);
        let n = avail.len().min(out.len());
        out[..n].copy_from_slice(&avail[..n]);
        self.pos += n;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    use std::time::{Duration, Instant};

    /// Bytes no two blocks share, so a block out of order or read twice shows.
    fn pattern(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
    }

    /// Gives its bytes `step` at a time (a file read in short pieces), then an error if asked.
    struct Dribble {
        data: Vec<u8>,
        at: usize,
        step: usize,
        fail_at_end: bool,
        reads: Arc<AtomicUsize>,
    }

    impl Read for Dribble {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            self.reads.fetch_add(1, Ordering::Relaxed);
            if self.at == self.data.len() && self.fail_at_end {
                return Err(io::Error::other("disk gone"));
            }
            let n = self.step.min(out.len()).min(self.data.len() - self.at);
            out[..n].copy_from_slice(&self.data[self.at..self.at + n]);
            self.at += n;
            Ok(n)
        }
    }

    fn dribble(data: &[u8], step: usize, fail_at_end: bool) -> (Dribble, Arc<AtomicUsize>) {
        let reads = Arc::new(AtomicUsize::new(0));
        let d = Dribble {
            data: data.to_vec(),
            at: 0,
            step,
            fail_at_end,
            reads: Arc::clone(&reads),
        };
        (d, reads)
    }

    fn read_all(r: &mut impl Read, piece: usize) -> io::Result<Vec<u8>> {
        let mut got = Vec::new();
        let mut buf = vec![0u8; piece];
        loop {
            let n = r.read(&mut buf)?;
            if n == 0 {
                return Ok(got);
            }
            got.extend_from_slice(&buf[..n]);
        }
    }

    #[test]
    fn gives_every_byte_in_order_whatever_the_piece_sizes() {
        // Around the block size: empty, less than a block, exactly one or two, and between.
        for len in [
            0,
            1,
            1000,
            BLOCK - 1,
            BLOCK,
            BLOCK + 1,
            2 * BLOCK,
            5 * BLOCK + 12_345,
        ] {
            let data = pattern(len);
            for (step, piece) in [(1 << 16, 16), (4096, 1 << 20), (usize::MAX, 777)] {
                let (d, _) = dribble(&data, step, false);
                let mut r = ReadAhead::spawn(d, "test-read-ahead").unwrap();
                let got = read_all(&mut r, piece).unwrap();
                assert!(got == data, "len {len}, step {step}, piece {piece}");
                // The end stays the end.
                assert_eq!(r.read(&mut [0u8; 8]).unwrap(), 0);
            }
        }
    }

    #[test]
    fn an_error_comes_after_the_bytes_read_before_it_and_ends_the_stream() {
        let data = pattern(BLOCK + 500);
        let (d, _) = dribble(&data, 1 << 16, true);
        let mut r = ReadAhead::spawn(d, "test-read-ahead").unwrap();
        let mut got = Vec::new();
        let mut piece = vec![0u8; 4096];
        let err = loop {
            match r.read(&mut piece) {
                Ok(0) => panic!("end before the error"),
                Ok(n) => got.extend_from_slice(&piece[..n]),
                Err(e) => break e,
            }
        };
        assert!(got == data);
        assert_eq!(err.to_string(), "disk gone");
        assert_eq!(r.read(&mut [0u8; 8]).unwrap(), 0);
    }

    #[test]
    fn memory_stays_bounded_when_the_parser_does_not_read() {
        // 64 blocks offered, none read: the thread stops after the channel's depth plus the
        // block it holds.
        let data = pattern(64 * BLOCK);
        let (d, reads) = dribble(&data, BLOCK, false);
        let r = ReadAhead::spawn(d, "test-read-ahead").unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let blocks_read = reads.load(Ordering::Relaxed);
        assert!(blocks_read <= DEPTH + 1, "{blocks_read} blocks read ahead");
        drop(r);
    }

    #[test]
    fn dropping_the_reader_stops_the_thread() {
        let data = pattern(64 * BLOCK);
        let (d, reads) = dribble(&data, BLOCK, false);
        let mut r = ReadAhead::spawn(d, "test-read-ahead").unwrap();
        let mut one = vec![0u8; 100];
        r.read_exact(&mut one).unwrap();
        drop(r);
        // The thread owns the only other handle on the counter: it is gone once the thread
        // has returned and dropped its reader.
        let start = Instant::now();
        while Arc::strong_count(&reads) > 1 {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "thread still running"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(reads.load(Ordering::Relaxed) <= DEPTH + 3);
    }
}
