//! Packet sequence counters: loss, late (reordered) and duplicate packets.
//!
//! A counter that steps by one per packet tells more than the time between packets: a packet
//! a little behind the latest came late (it fills a gap counted as lost when its successor
//! came), and one whose number was seen already is a copy (a switch or a capture tool that
//! sent it twice), whose points must not be added twice. The window remembers which of the
//! last [`REORDER_PACKETS`] numbers came, so a late packet un-counts its gap once and a copy
//! of it is still a copy.

use super::REORDER_PACKETS;

/// What a packet's number says of it, against the numbers seen before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeqStep {
    /// The first packet, or the next one after `lost` numbers that never came.
    Next {
        /// Numbers skipped (counted lost; a late packet may still fill one).
        lost: u64,
    },
    /// At most [`REORDER_PACKETS`] behind the latest and not seen before: reordered on the
    /// way. It fills one of the numbers counted lost; the latest stays the latest.
    Late,
    /// At most [`REORDER_PACKETS`] behind the latest, neither seen nor counted lost (it is
    /// from before the first number or a restart): reordered, with nothing to un-count.
    Stray,
    /// A number seen already (the latest or one in the window). A copy where its time is the
    /// same too (a real copy is the same bytes); the caller checks, as a counter stuck at one
    /// value or restarted repeats numbers without repeating packets.
    Duplicate,
    /// Too far ahead or behind to be loss or reordering: the counter restarted. The window
    /// starts again from this number.
    Jump,
}

/// The numbers seen lately of a counter that wraps at `2^bits`.
#[derive(Clone, Copy, Debug)]
pub struct SeqWindow {
    mask: u64,
    max_gap: u64,
    latest: Option<u64>,
    /// Bit `i`: number `latest − i` came.
    seen: u64,
    /// Bit `i`: number `latest − i` was skipped, counted lost, and has not come since.
    lost: u64,
}

impl SeqWindow {
    /// A window on a `bits`-bit counter (1 ≤ bits ≤ 64); a step ahead of more than `max_gap`
    /// numbers is a restart, not loss.
    pub const fn new(bits: u32, max_gap: u64) -> Self {
        let mask = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        Self {
            mask,
            max_gap,
            latest: None,
            seen: 0,
            lost: 0,
        }
    }

    /// The latest number (the largest, modulo the wrap), if any came.
    pub fn latest(&self) -> Option<u64> {
        self.latest
    }

    /// Forgets every number: the next one is a first.
    pub fn reset(&mut self) {
        self.latest = None;
        self.seen = 0;
        self.lost = 0;
    }

    /// Starts again from `n`, as a first number (a counter that restarted or repeats itself).
    pub fn restart(&mut self, n: u64) {
        self.latest = Some(n & self.mask);
        self.seen = 1;
        self.lost = 0;
    }

    /// Classifies number `n` and records it; a [`SeqStep::Jump`] restarts the window at `n`.
    pub fn step(&mut self, n: u64) -> SeqStep {
        self.classify(n, true)
    }

    /// [`Self::step`], but a jump leaves the window as it was: for the numbers of a stretch
    /// that is over (a frame before the open one), where a stray number must not undo it.
    pub fn step_within(&mut self, n: u64) -> SeqStep {
        self.classify(n, false)
    }

    fn classify(&mut self, n: u64, restart_on_jump: bool) -> SeqStep {
        let n = n & self.mask;
        let Some(latest) = self.latest else {
            self.restart(n);
            return SeqStep::Next { lost: 0 };
        };
        let behind = latest.wrapping_sub(n) & self.mask;
        if behind <= u64::from(REORDER_PACKETS) {
            let bit = 1u64 << behind;
            if self.seen & bit != 0 {
                return SeqStep::Duplicate;
            }
            self.seen |= bit;
            if self.lost & bit != 0 {
                self.lost &= !bit;
                return SeqStep::Late;
            }
            return SeqStep::Stray;
        }
        let ahead = n.wrapping_sub(latest) & self.mask;
        if ahead > self.max_gap {
            if restart_on_jump {
                self.restart(n);
            }
            return SeqStep::Jump;
        }
        // The numbers skipped are `1 … ahead − 1` behind the new latest.
        let (seen, lost, skipped) = if ahead >= 64 {
            (0, 0, u64::MAX - 1)
        } else {
            (self.seen << ahead, self.lost << ahead, (1u64 << ahead) - 2)
        };
        self.seen = seen | 1;
        self.lost = lost | skipped;
        self.latest = Some(n);
        SeqStep::Next { lost: ahead - 1 }
    }
}

/// The device times of a stream's last packets, for sensors whose packets carry no counter:
/// two packets of one sensor never share a time, so a packet whose time is among them is a
/// copy. It holds as many as a late packet can be behind ([`REORDER_PACKETS`]) and the latest.
#[derive(Clone, Copy, Debug, Default)]
pub struct RecentTimes {
    times: [i64; REORDER_PACKETS as usize + 1],
    len: usize,
    next: usize,
}

impl RecentTimes {
    /// Whether `t` is one of the times kept.
    pub fn contains(&self, t: i64) -> bool {
        self.times[..self.len].contains(&t)
    }

    /// Keeps `t`, forgetting the oldest once full.
    pub fn push(&mut self, t: i64) {
        self.times[self.next] = t;
        self.next = (self.next + 1) % self.times.len();
        self.len = (self.len + 1).min(self.times.len());
    }

    /// Forgets every time.
    pub fn clear(&mut self) {
        self.len = 0;
        self.next = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steps(w: &mut SeqWindow, ns: &[u64]) -> Vec<SeqStep> {
        ns.iter().map(|&n| w.step(n)).collect()
    }

    #[test]
    fn in_order_numbers_and_gaps() {
        let mut w = SeqWindow::new(16, 4096);
        use SeqStep::*;
        assert_eq!(
            steps(&mut w, &[7, 8, 9, 12, 13]),
            [
                Next { lost: 0 },
                Next { lost: 0 },
                Next { lost: 0 },
                Next { lost: 2 },
                Next { lost: 0 }
            ]
        );
    }

    #[test]
    fn the_wrap_is_a_step_like_any_other() {
        use SeqStep::*;
        let mut w = SeqWindow::new(16, 4096);
        // 65534, then 0 and 1 lost 65535: one lost across the wrap.
        assert_eq!(
            steps(&mut w, &[65_533, 65_534, 0, 1]),
            [
                Next { lost: 0 },
                Next { lost: 0 },
                Next { lost: 1 },
                Next { lost: 0 }
            ]
        );
        // A late packet across the wrap: 65535 after 0.
        let mut w = SeqWindow::new(16, 4096);
        assert_eq!(
            steps(&mut w, &[65_534, 0, 65_535, 1]),
            [Next { lost: 0 }, Next { lost: 1 }, Late, Next { lost: 0 }]
        );
        // 32-bit counter.
        let mut w = SeqWindow::new(32, 1 << 20);
        assert_eq!(
            steps(&mut w, &[u64::from(u32::MAX), 1]),
            [Next { lost: 0 }, Next { lost: 1 }]
        );
    }

    #[test]
    fn late_copies_and_restarts() {
        use SeqStep::*;
        let mut w = SeqWindow::new(16, 4096);
        assert_eq!(
            steps(&mut w, &[100, 102, 101, 101, 102, 103, 90, 91, 92]),
            [
                Next { lost: 0 },
                Next { lost: 1 },
                Late,
                Duplicate, // the late one again
                Duplicate, // 102 is no longer the latest but was seen
                Next { lost: 0 },
                Jump, // 13 behind: beyond the window, a restart
                Next { lost: 0 },
                Next { lost: 0 },
            ]
        );
        // Far ahead: a restart; the window forgets the old numbers.
        let mut w = SeqWindow::new(16, 4096);
        assert_eq!(
            steps(&mut w, &[5, 6, 30_000, 6]),
            [Next { lost: 0 }, Next { lost: 0 }, Jump, Jump]
        );
        // A step of 64 or more numbers clears every bit of the window but the skipped ones.
        let mut w = SeqWindow::new(16, 4096);
        assert_eq!(
            steps(&mut w, &[0, 100, 99, 1]),
            [Next { lost: 0 }, Next { lost: 99 }, Late, Jump]
        );
    }

    #[test]
    fn only_numbers_counted_lost_are_late() {
        use SeqStep::*;
        // After the first number and after a restart, a number just behind was never counted
        // lost: a stray, nothing to un-count.
        let mut w = SeqWindow::new(32, 1 << 20);
        assert_eq!(
            steps(&mut w, &[1_000, 995, 1_002, 1_001, 1_001, 998]),
            [
                Next { lost: 0 },
                Stray,
                Next { lost: 1 },
                Late,
                Duplicate,
                Stray
            ]
        );
        // A jump restarts the window; `step_within` leaves it.
        let mut w = SeqWindow::new(16, 4096);
        assert_eq!(
            steps(&mut w, &[10, 12]),
            [Next { lost: 0 }, Next { lost: 1 }]
        );
        assert_eq!(w.step_within(9_000), Jump);
        assert_eq!(w.latest(), Some(12));
        assert_eq!(w.step(11), Late);
        // A restart forgets the numbers counted lost.
        w.restart(500);
        assert_eq!(steps(&mut w, &[499, 500]), [Stray, Duplicate]);
    }

    #[test]
    fn recent_times_keep_the_last_eleven() {
        let mut r = RecentTimes::default();
        assert!(!r.contains(0), "an empty window holds no time, 0 included");
        for t in 0..20 {
            r.push(t * 10);
        }
        // 90..=190 kept, 80 forgotten.
        assert!(r.contains(190) && r.contains(90));
        assert!(!r.contains(80) && !r.contains(95));
        r.clear();
        assert!(!r.contains(190));
    }
}
