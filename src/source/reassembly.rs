//! IPv4 fragment reassembly, sans-IO.
//!
//! In: IPv4 fragments (key, offset, more-fragments flag, payload) with their capture or receive
//! time. Out: complete IP payloads (for UDP: header + data), lent from an internal buffer until
//! the next call. No I/O, no clock reads: time comes with each fragment, so the same code serves
//! pcap files (capture time) and a live socket path (receive time).
//!
//! Every Ouster lidar packet exceeds a 1500-byte MTU, so raw captures of Ouster sensors hold
//! IPv4 fragments (FORMATS.md, "Every Ouster lidar packet exceeds a 1500-byte MTU").
//!
//! # Rules
//! - A datagram is identified by (source, destination, protocol, IP id) ([`FragmentKey`]).
//! - Fragments may come in any order. Bytes already received win: a duplicate or overlapping
//!   fragment only fills holes and can never move data or write out of bounds.
//! - A datagram is complete when the last fragment (MF = 0) is there and no hole remains.
//! - **Timeout** by the fragments' own time: when a fragment arrives, every set whose *first*
//!   fragment is older than [`ReassemblyConfig::timeout_ns`] is dropped. This is what keeps a stale
//!   orphan from being glued to a later datagram that reuses its IP id (the real case in
//!   ouster-sdk's `duplicate_id.pcap`: an orphan first fragment 88 s before a complete datagram
//!   with the same id).
//! - **Bounded memory**: at most [`ReassemblyConfig::max_pending`] incomplete sets and
//!   [`ReassemblyConfig::max_bytes`] bytes of set buffers; beyond either, the oldest set is
//!   evicted. A set cannot hold more than [`MAX_INTERVALS`] disjoint byte ranges (hostile tiny
//!   fragments with holes) and no datagram exceeds [`MAX_IPV4_PAYLOAD`].
//! - Inconsistent fragments (a second, different end; data past the known end; a non-final
//!   fragment whose length is not a multiple of 8) are rejected, and the set they contradict is
//!   dropped, as Linux does with IPv4 queues that contradict themselves.
//!
//! Dropped sets are counted fragment by fragment in [`ReassemblyStats::expired_fragments`]
//! (sets in [`ReassemblyStats::expired_sets`]), so every accepted fragment ends up in exactly one
//! of: a reassembled datagram, a duplicate, an expired set, or a still-pending set.

use std::net::Ipv4Addr;

/// Largest IPv4 payload: 65535-byte total length minus a 20-byte header.
pub const MAX_IPV4_PAYLOAD: usize = 65_535 - 20;
/// Most disjoint byte ranges one set may hold before it is dropped.
pub const MAX_INTERVALS: usize = 512;
/// Spare set buffers kept for reuse.
const SPARE_SETS: usize = 8;

/// Identifies the datagram a fragment belongs to (RFC 791).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FragmentKey {
    /// Source address.
    pub src: Ipv4Addr,
    /// Destination address.
    pub dst: Ipv4Addr,
    /// IP protocol (17 = UDP).
    pub protocol: u8,
    /// IP identification field.
    pub id: u16,
}

/// Limits of a [`Reassembler`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReassemblyConfig {
    /// A set whose first fragment is older than this (by the fragments' own time) is dropped when
    /// any later fragment arrives. Default 1 s: the fragments of one datagram arrive within
    /// microseconds, while a sender wraps its 16-bit IP id only after 65536 datagrams (about
    /// 90 s at the ~740 datagrams/s of an Ouster at 1024×10).
    pub timeout_ns: i64,
    /// Incomplete sets held at most. Default 64.
    pub max_pending: usize,
    /// Bytes of incomplete-set buffers held at most (each set's buffer extends to the furthest
    /// byte received). Default 8 MiB.
    pub max_bytes: usize,
}

impl Default for ReassemblyConfig {
    fn default() -> Self {
        Self {
            timeout_ns: 1_000_000_000,
            max_pending: 64,
            max_bytes: 8 << 20,
        }
    }
}

/// Counters of a [`Reassembler`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReassemblyStats {
    /// Fragments accepted (duplicates included, rejected fragments excluded).
    pub fragments: u64,
    /// Accepted fragments that brought no new byte.
    pub duplicates: u64,
    /// Accepted fragments that overlapped bytes already received (and brought new ones).
    pub overlaps: u64,
    /// Fragments rejected as inconsistent (see [`FragmentError`]).
    pub rejected: u64,
    /// Datagrams completed.
    pub reassembled: u64,
    /// Sets dropped incomplete: timeout, memory bound, contradiction, or [`Reassembler::expire_all`].
    pub expired_sets: u64,
    /// Accepted fragments in those dropped sets (duplicates included).
    pub expired_fragments: u64,
}

/// Why a fragment was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FragmentError {
    /// A non-final fragment without payload.
    #[error("fragment at offset {offset} has more-fragments set but no payload")]
    Empty {
        /// Fragment offset, bytes.
        offset: usize,
    },
    /// A non-final fragment whose offset or length is not a multiple of 8 bytes.
    #[error("non-final fragment at offset {offset} has length {len}, not a multiple of 8")]
    Misaligned {
        /// Fragment offset, bytes.
        offset: usize,
        /// Payload length, bytes.
        len: usize,
    },
    /// The fragment ends past the largest IPv4 payload.
    #[error("fragment ends at byte {end}, past the largest IPv4 payload ({MAX_IPV4_PAYLOAD})")]
    TooLong {
        /// End of the fragment, bytes.
        end: usize,
    },
    /// The fragment contradicts the datagram's end known from other fragments.
    #[error("fragment ending at byte {end} contradicts the datagram length {total}")]
    Inconsistent {
        /// End of the fragment, bytes.
        end: usize,
        /// Datagram length known from the final fragment, or bytes already received past a
        /// newly claimed end.
        total: usize,
    },
}

/// What [`Reassembler::push`] did with a fragment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Push {
    /// Stored; the datagram is still incomplete.
    Pending,
    /// The datagram is complete: [`Reassembler::completed`] holds its `len` payload bytes.
    Complete {
        /// Length of the reassembled IP payload.
        len: usize,
    },
    /// Accepted but dropped at once with its set, because the set alone exceeds
    /// [`ReassemblyConfig::max_bytes`] or [`MAX_INTERVALS`] (counted as expired).
    Dropped,
    /// Rejected as inconsistent (and the set it contradicted, if any, dropped).
    Rejected(FragmentError),
}

/// One datagram being reassembled.
#[derive(Debug, Default)]
struct FragmentSet {
    key: Option<FragmentKey>,
    first_ns: i64,
    /// Payload bytes; its length is the furthest byte received (holes are zero).
    data: Vec<u8>,
    /// Received byte ranges, sorted, disjoint and non-adjacent.
    covered: Vec<(usize, usize)>,
    /// Payload length, known once the final fragment arrived.
    total: Option<usize>,
    /// Accepted fragments in this set.
    fragments: u64,
}

impl FragmentSet {
    fn is_complete(&self) -> bool {
        matches!((self.total, self.covered.as_slice()), (Some(t), &[(0, end)]) if end == t)
    }

    /// Copies the parts of `payload` (placed at `offset`) that fall in holes. Returns the number of
    /// new bytes. `self.data` must already reach `offset + payload.len()`.
    fn fill_holes(&mut self, offset: usize, payload: &[u8]) -> usize {
        let end = offset + payload.len();
        let mut copied = 0;
        let mut pos = offset;
        let mut copy = |data: &mut Vec<u8>, from: usize, to: usize| {
            if let (Some(dst), Some(src)) = (
                data.get_mut(from..to),
                payload.get(from - offset..to - offset),
            ) {
                dst.copy_from_slice(src);
                copied += to - from;
            }
        };
        for &(a, b) in &self.covered {
            if b <= pos {
                continue;
            }
            if a >= end {
                break;
            }
            if a > pos {
                copy(&mut self.data, pos, a);
            }
            pos = b;
            if pos >= end {
                break;
            }
        }
        if pos < end {
            copy(&mut self.data, pos, end);
        }
        copied
    }

    /// Adds `[start, end)` to the covered ranges, merging with overlapping or adjacent ones.
    fn cover(&mut self, start: usize, end: usize) {
        // First range that reaches `start` (touching counts) and first one past `end`.
        let first = self.covered.partition_point(|&(_, b)| b < start);
        let last = self.covered.partition_point(|&(a, _)| a <= end);
        if first >= last {
            self.covered.insert(first, (start, end));
            return;
        }
        let (mut lo, mut hi) = (start, end);
        if let (Some(&(a, _)), Some(&(_, b))) =
            (self.covered.get(first), self.covered.get(last - 1))
        {
            lo = lo.min(a);
            hi = hi.max(b);
        }
        self.covered.drain(first + 1..last);
        if let Some(slot) = self.covered.get_mut(first) {
            *slot = (lo, hi);
        }
    }

    fn max_end(&self) -> usize {
        self.covered.last().map_or(0, |&(_, b)| b)
    }
}

/// Reassembles IPv4 datagrams from fragments, within fixed memory bounds.
///
/// ```
/// use ringscan::source::reassembly::{FragmentKey, Push, Reassembler};
/// use std::net::Ipv4Addr;
///
/// let key = FragmentKey { src: Ipv4Addr::new(10, 0, 0, 1), dst: Ipv4Addr::BROADCAST, protocol: 17, id: 7 };
/// let mut r = Reassembler::default();
/// assert_eq!(r.push(0, key, 8, false, b"tail"), Push::Pending);
/// assert_eq!(r.push(5, key, 0, true, b"01234567"), Push::Complete { len: 12 });
/// assert_eq!(r.completed(), b"01234567tail");
/// ```
#[derive(Debug, Default)]
pub struct Reassembler {
    config: ReassemblyConfig,
    /// Incomplete sets, oldest first (arrival order of their first fragment).
    sets: Vec<FragmentSet>,
    /// Sum of `data.len()` over `sets`.
    pending_bytes: usize,
    spare: Vec<FragmentSet>,
    done: Vec<u8>,
    stats: ReassemblyStats,
}

impl Reassembler {
    /// A reassembler with the given limits.
    pub fn new(config: ReassemblyConfig) -> Self {
        Self {
            config,
            ..Self::default()
        }
    }

    /// Its limits.
    pub fn config(&self) -> &ReassemblyConfig {
        &self.config
    }

    /// Its counters.
    pub fn stats(&self) -> &ReassemblyStats {
        &self.stats
    }

    /// Incomplete sets held now.
    pub fn pending_sets(&self) -> usize {
        self.sets.len()
    }

    /// Bytes of incomplete-set buffers held now (≤ [`ReassemblyConfig::max_bytes`]).
    pub fn pending_bytes(&self) -> usize {
        self.pending_bytes
    }

    /// The last datagram payload completed by [`push`](Self::push).
    pub fn completed(&self) -> &[u8] {
        &self.done
    }

    /// Adds one fragment received at `time_ns`: `payload` is the IP payload of the fragment,
    /// placed at `offset` bytes (the header field × 8); `more` is the more-fragments flag.
    pub fn push(
        &mut self,
        time_ns: i64,
        key: FragmentKey,
        offset: usize,
        more: bool,
        payload: &[u8],
    ) -> Push {
        let Some(end) = offset.checked_add(payload.len()) else {
            return self.reject(FragmentError::TooLong { end: usize::MAX });
        };
        if end > MAX_IPV4_PAYLOAD {
            return self.reject(FragmentError::TooLong { end });
        }
        if more && payload.is_empty() {
            return self.reject(FragmentError::Empty { offset });
        }
        if offset % 8 != 0 || (more && payload.len() % 8 != 0) {
            return self.reject(FragmentError::Misaligned {
                offset,
                len: payload.len(),
            });
        }

        self.expire(time_ns);
        let index = match self.sets.iter().position(|s| s.key == Some(key)) {
            Some(i) => i,
            None => self.open(key, time_ns),
        };

        // Consistency with what the set already knows about the datagram's end.
        let Some(set) = self.sets.get(index) else {
            return Push::Pending;
        };
        let contradiction = match (more, set.total) {
            (false, Some(total)) if total != end => Some(total),
            (false, None) if set.max_end() > end => Some(set.max_end()),
            (true, Some(total)) if end > total => Some(total),
            _ => None,
        };
        if let Some(total) = contradiction {
            self.drop_set(index);
            return self.reject(FragmentError::Inconsistent { end, total });
        }

        self.store(index, offset, more, payload, end)
    }

    /// Second half of [`push`](Self::push), once the set is chosen and checked.
    fn store(
        &mut self,
        mut index: usize,
        offset: usize,
        more: bool,
        payload: &[u8],
        end: usize,
    ) -> Push {
        // Memory: grow the set's buffer only within the byte bound, evicting the oldest other
        // sets first, and this set itself if it alone is too large.
        let growth = self
            .sets
            .get(index)
            .map_or(0, |s| end.saturating_sub(s.data.len()));
        while self.pending_bytes + growth > self.config.max_bytes && self.sets.len() > 1 {
            let oldest_other = usize::from(index == 0);
            self.drop_set(oldest_other);
            if oldest_other < index {
                index -= 1;
            }
        }
        if self.pending_bytes + growth > self.config.max_bytes {
            self.stats.fragments += 1;
            self.drop_set_counting(index, 1);
            return Push::Dropped;
        }
        let Some(set) = self.sets.get_mut(index) else {
            return Push::Pending;
        };
        if set.data.len() < end {
            set.data.resize(end, 0);
            self.pending_bytes += growth;
        }
        self.stats.fragments += 1;
        set.fragments += 1;
        let new_bytes = set.fill_holes(offset, payload);
        if new_bytes == 0 {
            self.stats.duplicates += u64::from(!payload.is_empty());
        } else {
            set.cover(offset, end);
            if new_bytes < payload.len() {
                self.stats.overlaps += 1;
            }
        }
        if !more {
            set.total = Some(end);
        }
        if set.covered.len() > MAX_INTERVALS {
            self.drop_set(index);
            return Push::Dropped;
        }
        if !set.is_complete() {
            return Push::Pending;
        }

        // Complete: hand the buffer over to `done` and recycle the set.
        let mut set = self.sets.remove(index);
        self.pending_bytes = self.pending_bytes.saturating_sub(set.data.len());
        std::mem::swap(&mut self.done, &mut set.data);
        let len = set.total.unwrap_or(end).min(self.done.len());
        self.done.truncate(len);
        self.stats.reassembled += 1;
        self.recycle(set);
        Push::Complete { len }
    }

    /// Drops every set whose first fragment is older than the timeout at `now_ns`.
    ///
    /// [`push`](Self::push) calls this itself; a live source may call it on a timer too.
    pub fn expire(&mut self, now_ns: i64) {
        let timeout = self.config.timeout_ns;
        let mut i = 0;
        while i < self.sets.len() {
            let stale = self
                .sets
                .get(i)
                .is_some_and(|s| now_ns.saturating_sub(s.first_ns) > timeout);
            if stale {
                self.drop_set(i);
            } else {
                i += 1;
            }
        }
    }

    /// Drops every incomplete set (end of a capture), counting them as expired.
    pub fn expire_all(&mut self) {
        while !self.sets.is_empty() {
            self.drop_set(0);
        }
    }

    fn reject(&mut self, error: FragmentError) -> Push {
        self.stats.rejected += 1;
        Push::Rejected(error)
    }

    /// Opens a set for `key`, evicting the oldest if the count bound is reached.
    fn open(&mut self, key: FragmentKey, time_ns: i64) -> usize {
        while self.sets.len() >= self.config.max_pending.max(1) {
            self.drop_set(0);
        }
        let mut set = self.spare.pop().unwrap_or_default();
        set.key = Some(key);
        set.first_ns = time_ns;
        self.sets.push(set);
        self.sets.len() - 1
    }

    fn drop_set(&mut self, index: usize) {
        self.drop_set_counting(index, 0);
    }

    /// Drops a set, counting its fragments plus `extra` as expired.
    fn drop_set_counting(&mut self, index: usize, extra: u64) {
        if index >= self.sets.len() {
            return;
        }
        let set = self.sets.remove(index);
        self.pending_bytes = self.pending_bytes.saturating_sub(set.data.len());
        self.stats.expired_sets += 1;
        self.stats.expired_fragments += set.fragments + extra;
        self.recycle(set);
    }

    fn recycle(&mut self, mut set: FragmentSet) {
        if self.spare.len() < SPARE_SETS {
            set.key = None;
            set.data.clear();
            set.covered.clear();
            set.total = None;
            set.fragments = 0;
            self.spare.push(set);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KEY: FragmentKey = FragmentKey {
        src: Ipv4Addr::new(10, 5, 6, 101),
        dst: Ipv4Addr::new(10, 5, 6, 1),
        protocol: 17,
        id: 21723,
    };

    /// A datagram of `len` bytes with a recognisable pattern.
    fn datagram(len: usize) -> Vec<u8> {
        (0..len).map(|i| (i * 7 + i / 251) as u8).collect()
    }

    /// Splits `data` into fragments of `mtu` payload bytes: (offset, more, bytes).
    fn fragments(data: &[u8], mtu: usize) -> Vec<(usize, bool, Vec<u8>)> {
        let chunks: Vec<_> = data.chunks(mtu).collect();
        chunks
            .iter()
            .enumerate()
            .map(|(i, c)| (i * mtu, i + 1 < chunks.len(), c.to_vec()))
            .collect()
    }

    /// Feeds fragments in the given order; returns the datagrams completed.
    fn feed(r: &mut Reassembler, frags: &[(usize, bool, Vec<u8>)]) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for (t, (offset, more, bytes)) in frags.iter().enumerate() {
            if let Push::Complete { len } = r.push(t as i64, KEY, *offset, *more, bytes) {
                assert_eq!(len, r.completed().len());
                out.push(r.completed().to_vec());
            }
        }
        out
    }

    /// xorshift64: a deterministic shuffle without a dependency.
    fn shuffle<T>(items: &mut [T], mut seed: u64) {
        for i in (1..items.len()).rev() {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            items.swap(i, (seed % (i as u64 + 1)) as usize);
        }
    }

    #[test]
    fn in_order() {
        let data = datagram(8448);
        let mut r = Reassembler::default();
        assert_eq!(feed(&mut r, &fragments(&data, 1480)), vec![data]);
        assert_eq!(r.stats().fragments, 6);
        assert_eq!(r.stats().reassembled, 1);
        assert_eq!((r.pending_sets(), r.pending_bytes()), (0, 0));
    }

    #[test]
    fn reversed() {
        let data = datagram(16640);
        let mut frags = fragments(&data, 1480);
        frags.reverse();
        let mut r = Reassembler::default();
        assert_eq!(feed(&mut r, &frags), vec![data]);
    }

    #[test]
    fn shuffled() {
        let data = datagram(MAX_IPV4_PAYLOAD);
        for seed in 1..50 {
            let mut frags = fragments(&data, 1480);
            shuffle(&mut frags, seed);
            let mut r = Reassembler::default();
            assert_eq!(feed(&mut r, &frags), vec![data.clone()], "seed {seed}");
            assert_eq!(r.pending_bytes(), 0);
        }
    }

    #[test]
    fn duplicated_fragments_are_ignored() {
        let data = datagram(5000);
        let mut frags = fragments(&data, 1480);
        let dup = frags.clone();
        frags.insert(1, dup[0].clone());
        frags.insert(3, dup[1].clone());
        // A duplicate of the final fragment after completion starts a new, incomplete set.
        let mut r = Reassembler::default();
        assert_eq!(feed(&mut r, &frags), vec![data]);
        assert_eq!(r.stats().duplicates, 2);
        assert_eq!(r.stats().fragments, 6);
    }

    #[test]
    fn overlapping_fragments_fill_holes_only() {
        let data = datagram(4000);
        // Fragments of 1480 and, overlapping them, of 1000 at other offsets; shuffled.
        let mut frags = fragments(&data, 1480);
        let mut other = fragments(&data, 1000);
        other.retain(|f| f.1); // only non-final ones, so just one final fragment exists
        frags.extend(other);
        for seed in 1..30 {
            let mut frags = frags.clone();
            shuffle(&mut frags, seed);
            let mut r = Reassembler::default();
            let got = feed(&mut r, &frags);
            assert_eq!(got.first(), Some(&data), "seed {seed}");
        }
    }

    #[test]
    fn overlap_with_different_bytes_keeps_the_first() {
        let mut r = Reassembler::default();
        assert_eq!(r.push(0, KEY, 0, true, &[1; 16]), Push::Pending);
        assert_eq!(r.push(0, KEY, 8, true, &[2; 16]), Push::Pending);
        assert_eq!(
            r.push(0, KEY, 24, false, &[3; 4]),
            Push::Complete { len: 28 }
        );
        let mut expected = vec![1; 16];
        expected.extend([2; 8]);
        expected.extend([3; 4]);
        assert_eq!(r.completed(), expected.as_slice());
        assert_eq!(r.stats().overlaps, 1);
    }

    #[test]
    fn inconsistent_fragments_are_rejected_and_drop_the_set() {
        let mut r = Reassembler::default();
        assert_eq!(r.push(0, KEY, 0, true, &[0; 16]), Push::Pending);
        assert_eq!(r.push(0, KEY, 24, false, &[0; 8]), Push::Pending);
        // Ends past the datagram's end.
        assert!(matches!(
            r.push(0, KEY, 16, true, &[0; 24]),
            Push::Rejected(FragmentError::Inconsistent { end: 40, total: 32 })
        ));
        assert_eq!(r.pending_sets(), 0);
        assert_eq!(r.stats().expired_fragments, 2);
        // Misaligned, empty, too long.
        assert!(matches!(
            r.push(0, KEY, 0, true, &[0; 12]),
            Push::Rejected(FragmentError::Misaligned { .. })
        ));
        assert!(matches!(
            r.push(0, KEY, 8, true, &[]),
            Push::Rejected(FragmentError::Empty { .. })
        ));
        assert!(matches!(
            r.push(0, KEY, 65_528, false, &[0; 16]),
            Push::Rejected(FragmentError::TooLong { end: 65_544 })
        ));
        assert_eq!(r.stats().rejected, 4);
        assert_eq!(r.pending_sets(), 0);
        // A second final fragment with another end, and a final fragment before received data.
        assert_eq!(r.push(0, KEY, 0, false, &[0; 8]), Push::Complete { len: 8 });
        assert_eq!(r.push(0, KEY, 16, true, &[0; 8]), Push::Pending);
        assert!(matches!(
            r.push(0, KEY, 8, false, &[0; 4]),
            Push::Rejected(FragmentError::Inconsistent { end: 12, total: 24 })
        ));
        assert_eq!(r.push(0, KEY, 16, false, &[0; 8]), Push::Pending);
        assert!(matches!(
            r.push(0, KEY, 32, false, &[0; 8]),
            Push::Rejected(FragmentError::Inconsistent { end: 40, total: 24 })
        ));
    }

    #[test]
    fn stale_orphan_is_not_glued_to_a_later_datagram_with_the_same_id() {
        // The duplicate_id.pcap case: a first fragment, then 88 s later a whole datagram
        // reusing the IP id.
        let orphan = datagram(1480);
        let data: Vec<u8> = datagram(8448).iter().map(|b| b ^ 0x5a).collect();
        let mut r = Reassembler::default();
        assert_eq!(r.push(0, KEY, 0, true, &orphan), Push::Pending);
        let mut done = Vec::new();
        for (offset, more, bytes) in fragments(&data, 1480)
            .iter()
            .skip(1)
            .chain(fragments(&data, 1480).iter().take(1))
        {
            if let Push::Complete { .. } = r.push(88_000_000_000, KEY, *offset, *more, bytes) {
                done.push(r.completed().to_vec());
            }
        }
        assert_eq!(done, vec![data]);
        assert_eq!(r.stats().expired_sets, 1);
        assert_eq!(r.stats().expired_fragments, 1);
    }

    #[test]
    fn within_the_timeout_a_set_survives() {
        let mut r = Reassembler::new(ReassemblyConfig {
            timeout_ns: 10,
            ..Default::default()
        });
        assert_eq!(r.push(100, KEY, 0, true, &[1; 8]), Push::Pending);
        assert_eq!(
            r.push(110, KEY, 8, false, &[2; 8]),
            Push::Complete { len: 16 }
        );
        assert_eq!(r.push(200, KEY, 0, true, &[1; 8]), Push::Pending);
        assert_eq!(r.push(211, KEY, 8, false, &[2; 8]), Push::Pending);
        assert_eq!(r.stats().expired_fragments, 1);
        // Time going backwards never expires anything.
        assert_eq!(r.push(0, KEY, 0, true, &[1; 8]), Push::Complete { len: 16 });
    }

    #[test]
    fn lone_first_fragments_stay_within_the_set_bound() {
        let mut r = Reassembler::default();
        for i in 0..100_000_u32 {
            let key = FragmentKey {
                id: i as u16,
                src: Ipv4Addr::from(i),
                ..KEY
            };
            assert_eq!(
                r.push(i64::from(i), key, 0, true, &[0; 1480]),
                Push::Pending
            );
            assert!(r.pending_sets() <= 64);
            assert!(r.pending_bytes() <= 64 * 1480);
        }
        assert_eq!(r.pending_sets(), 64);
        assert_eq!(r.pending_bytes(), 64 * 1480);
        assert_eq!(r.stats().expired_fragments, 100_000 - 64);
        r.expire_all();
        assert_eq!((r.pending_sets(), r.pending_bytes()), (0, 0));
        assert_eq!(r.stats().expired_fragments, 100_000);
    }

    #[test]
    fn byte_bound_evicts_oldest_and_refuses_oversized_sets() {
        let config = ReassemblyConfig {
            max_bytes: 10_000,
            ..Default::default()
        };
        let mut r = Reassembler::new(config);
        for i in 0..100_000_u32 {
            let key = FragmentKey {
                id: i as u16,
                src: Ipv4Addr::from(i),
                ..KEY
            };
            // Far fragments: each set's buffer reaches offset + len.
            let offset = (i as usize % 8) * 1480;
            r.push(0, key, offset, true, &[0; 1480]);
            assert!(r.pending_bytes() <= 10_000, "at {i}: {}", r.pending_bytes());
        }
        // A set that alone exceeds the bound is dropped at once.
        let key = FragmentKey {
            id: 1,
            src: Ipv4Addr::new(1, 1, 1, 1),
            ..KEY
        };
        assert_eq!(r.push(0, key, 20_000, true, &[0; 8]), Push::Dropped);
        assert!(r.pending_bytes() <= 10_000);
    }

    #[test]
    fn tiny_fragments_with_holes_are_bounded() {
        let mut r = Reassembler::default();
        let mut dropped = false;
        for k in 0..2_000 {
            match r.push(0, KEY, k * 16, true, &[0; 8]) {
                Push::Pending => {}
                Push::Dropped => {
                    dropped = true;
                    break;
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(dropped);
        assert_eq!(r.pending_sets(), 0);
    }

    #[test]
    fn arbitrary_fragments_never_panic() {
        let mut r = Reassembler::new(ReassemblyConfig {
            max_bytes: 100_000,
            max_pending: 4,
            timeout_ns: 50,
        });
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for t in 0..200_000_i64 {
            let v = next();
            let key = FragmentKey {
                id: (v % 3) as u16,
                ..KEY
            };
            let offset = ((v >> 8) % 80) as usize * 8;
            let len = ((v >> 20) % 100) as usize;
            let more = (v >> 40) % 4 != 0;
            let payload = vec![(v >> 48) as u8; len];
            if let Push::Complete { len } = r.push(t / 10, key, offset, more, &payload) {
                assert_eq!(r.completed().len(), len);
            }
            assert!(r.pending_bytes() <= 100_000);
            assert!(r.pending_sets() <= 4);
        }
        let s = r.stats().clone();
        assert!(s.reassembled > 0);
        r.expire_all();
        assert_eq!(r.pending_bytes(), 0);
    }
}
