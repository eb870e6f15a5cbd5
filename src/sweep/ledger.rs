//! Which numbers of one run of a 16-bit packet counter (a frame, or the numbers since the
//! counter last restarted) came and which were counted lost: Livox's SDK2 `udp_cnt`, the
//! Robosense M1's `pkt_seq` (one run a frame), a spinning Robosense's packet places in time
//! (header time over the packet period: it sends no counter).
//!
//! The shared [`crate::sweep::SeqWindow`] remembers the last [`REORDER_PACKETS`] numbers,
//! which is enough to tell a reordered packet from a loss but not to account for one that
//! comes later still: a packet 11 behind, or one of a frame already closed, looked like a
//! restart (or a copy), and the gap it left stayed counted lost. The ledger keeps the last
//! [`LEDGER_NUMBERS`] numbers of the run (about two 100 ms periods of the fastest Livox, the
//! HAP; three M1 frames in dual return), so such a packet un-counts its loss exactly once
//! and a copy of it is a copy.

use crate::sweep::REORDER_PACKETS;

/// Numbers kept: a divisor of 2^16, so a number's bit stays put across the counter's wrap.
pub const LEDGER_NUMBERS: u16 = 4096;
const WORDS: usize = LEDGER_NUMBERS as usize / 64;

/// What a number is, against the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Count {
    /// The first number, or ahead of the latest by at most `max_gap`, `lost` skipped.
    Next {
        /// Numbers skipped.
        lost: u64,
    },
    /// In the run and come already: a copy, or the counter repeating itself.
    Seen {
        /// Numbers behind the latest.
        behind: u16,
    },
    /// In the run, counted lost and not come since: late.
    Lost {
        /// Numbers behind the latest.
        behind: u16,
    },
    /// Just before the run's first number (at most [`REORDER_PACKETS`] behind the latest):
    /// reordered, with nothing counted lost to un-count.
    Stray,
    /// Neither in the run nor a step ahead: a restart, or a packet from before the run.
    Far,
}

/// One run's numbers.
#[derive(Clone, Debug)]
pub struct UdpLedger {
    max_gap: u64,
    latest: Option<u16>,
    /// The run's numbers kept: `latest − len + 1 ..= latest` (mod 2^16).
    len: u16,
    /// Bit `n mod LEDGER_NUMBERS`: number `n` came.
    seen: [u64; WORDS],
    /// Bit `n mod LEDGER_NUMBERS`: number `n` was counted lost and has not come since.
    lost: [u64; WORDS],
}

fn bit(n: u16) -> (usize, u64) {
    let i = usize::from(n % LEDGER_NUMBERS);
    (i / 64, 1u64 << (i % 64))
}

impl UdpLedger {
    /// An empty ledger; a step ahead of more than `max_gap` is no loss.
    pub fn new(max_gap: u64) -> Self {
        Self {
            max_gap,
            latest: None,
            len: 0,
            seen: [0; WORDS],
            lost: [0; WORDS],
        }
    }

    /// The latest number (the largest, modulo the wrap), if any came.
    pub fn latest(&self) -> Option<u16> {
        self.latest
    }

    /// Forgets every number.
    pub fn reset(&mut self) {
        self.latest = None;
        self.len = 0;
        self.seen = [0; WORDS];
        self.lost = [0; WORDS];
    }

    /// What `n` is; nothing recorded.
    pub fn peek(&self, n: u16) -> Count {
        let Some(latest) = self.latest else {
            return Count::Next { lost: 0 };
        };
        let behind = latest.wrapping_sub(n);
        if behind < self.len {
            let (w, b) = bit(n);
            if self.seen[w] & b != 0 {
                return Count::Seen { behind };
            }
            if self.lost[w] & b != 0 {
                return Count::Lost { behind };
            }
            // Kept but neither: from before the run's first number (a stray widened it).
        }
        if behind <= REORDER_PACKETS {
            return Count::Stray;
        }
        let ahead = u64::from(n.wrapping_sub(latest));
        if ahead <= self.max_gap {
            return Count::Next { lost: ahead - 1 };
        }
        Count::Far
    }

    /// Records `n` as come (a [`Count::Far`] restarts the run at `n`); returns what it was.
    pub fn take(&mut self, n: u16) -> Count {
        let c = self.peek(n);
        match c {
            Count::Next { lost } => match self.latest {
                None => self.restart(n),
                Some(latest) => {
                    for k in 1..=lost {
                        self.mark(latest.wrapping_add(k as u16), false);
                    }
                    self.mark(n, true);
                    self.latest = Some(n);
                    let grown = u64::from(self.len) + lost + 1;
                    self.len = grown.min(u64::from(LEDGER_NUMBERS)) as u16;
                }
            },
            Count::Seen { .. } => {}
            Count::Lost { .. } => self.mark(n, true),
            Count::Stray => self.widen_to(n),
            Count::Far => self.restart(n),
        }
        c
    }

    /// Records `n`, a number from before the run's first ([`Count::Far`]) that came all the
    /// same (a late packet), as come: the run is widened back to it, so a copy of it is
    /// [`Count::Seen`]. Returns `false`, recording nothing, where `n` is not far or is further
    /// behind the latest than the ledger holds.
    pub fn take_before(&mut self, n: u16) -> bool {
        let Some(latest) = self.latest else {
            return false;
        };
        if self.peek(n) != Count::Far || latest.wrapping_sub(n) >= LEDGER_NUMBERS {
            return false;
        }
        self.widen_to(n);
        true
    }

    /// Widens the run back to `n` (at most [`LEDGER_NUMBERS`] behind the latest) and marks it
    /// come.
    fn widen_to(&mut self, n: u16) {
        let behind = self.latest.map_or(0, |l| l.wrapping_sub(n));
        // The numbers between the run's first and this one never came and were never
        // counted: neither bit.
        while self.len <= behind {
            let k = self.latest.unwrap_or(0).wrapping_sub(self.len);
            let (w, b) = bit(k);
            self.seen[w] &= !b;
            self.lost[w] &= !b;
            self.len += 1;
        }
        self.mark(n, true);
    }

    /// Starts a run at `n`, as a first number.
    pub fn restart(&mut self, n: u16) {
        self.start_at(n, false);
    }

    /// Starts a run at `n` (< [`LEDGER_NUMBERS`]) whose numbers `0 .. n` were sent and not
    /// come: counted lost (a frame whose first packets were lost).
    pub fn start_lost_before(&mut self, n: u16) {
        self.start_at(n, true);
    }

    fn start_at(&mut self, n: u16, lost_before: bool) {
        self.reset();
        self.latest = Some(n);
        self.len = 1;
        if lost_before && n < LEDGER_NUMBERS {
            for k in 0..n {
                self.mark(k, false);
            }
            self.len = n + 1;
        }
        self.mark(n, true);
    }

    fn mark(&mut self, n: u16, came: bool) {
        let (w, b) = bit(n);
        if came {
            self.seen[w] |= b;
            self.lost[w] &= !b;
        } else {
            self.seen[w] &= !b;
            self.lost[w] |= b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn takes(l: &mut UdpLedger, ns: &[u16]) -> Vec<Count> {
        ns.iter().map(|&n| l.take(n)).collect()
    }

    #[test]
    fn gaps_late_copies_far_behind() {
        use Count::*;
        let mut l = UdpLedger::new(4096);
        assert_eq!(
            takes(&mut l, &[7, 8, 10, 9, 9, 40, 20, 20, 8]),
            [
                Next { lost: 0 },
                Next { lost: 0 },
                Next { lost: 1 },
                Lost { behind: 1 },
                Seen { behind: 1 },
                Next { lost: 29 },
                Lost { behind: 20 }, // 20 behind: still the run's, counted lost
                Seen { behind: 20 },
                Seen { behind: 32 },
            ]
        );
        // Before the run's first: far, a restart.
        assert_eq!(l.peek(2), Far);
        // Just before it: a stray, within the reorder window.
        let mut l = UdpLedger::new(4096);
        assert_eq!(
            takes(&mut l, &[100, 95, 95, 97]),
            [Next { lost: 0 }, Stray, Seen { behind: 5 }, Stray]
        );
    }

    #[test]
    fn the_wrap_and_the_window_s_end() {
        use Count::*;
        let mut l = UdpLedger::new(4096);
        assert_eq!(
            takes(&mut l, &[65_534, 1, 65_535]),
            [Next { lost: 0 }, Next { lost: 2 }, Lost { behind: 2 }]
        );
        assert_eq!(l.take(0), Lost { behind: 1 });
        // 5000 numbers on: the run keeps the last 4096.
        for k in 2..5_002u16 {
            assert_eq!(l.take(k), Next { lost: 0 });
        }
        assert_eq!(l.peek(5_001 - 4_095), Seen { behind: 4_095 });
        assert_eq!(l.peek(5_001 - 4_096), Far);
    }

    #[test]
    fn a_run_started_after_lost_numbers() {
        use Count::*;
        let mut l = UdpLedger::new(4096);
        l.start_lost_before(3);
        assert_eq!(
            takes(&mut l, &[1, 1, 4, 0, 2]),
            [
                Lost { behind: 2 },
                Seen { behind: 2 },
                Next { lost: 0 },
                Lost { behind: 4 },
                Lost { behind: 2 }
            ]
        );
        // Never more than the ledger holds: nothing before 5000 counted lost.
        l.start_lost_before(5_000);
        assert_eq!(l.peek(4_999), Stray);
    }

    #[test]
    fn a_number_from_before_the_run_is_kept_once_taken() {
        use Count::*;
        let mut l = UdpLedger::new(4096);
        assert_eq!(takes(&mut l, &[500, 501, 502]), [Next { lost: 0 }; 3]);
        assert_eq!(l.peek(450), Far);
        assert!(l.take_before(450));
        assert_eq!(l.peek(450), Seen { behind: 52 });
        // Between it and the run's first: neither come nor counted, far as before.
        assert_eq!(l.peek(470), Far);
        assert_eq!(l.take(503), Next { lost: 0 });
        // Beyond what the ledger holds: nothing recorded.
        let beyond = 503u16.wrapping_sub(4_096);
        assert!(!l.take_before(beyond));
        assert_eq!(l.peek(beyond), Far);
    }
}
