//! An order-sensitive digest of an event stream, so two places in a graph can prove they saw the
//! same events, each exactly once and in the same order.

use serde::{Deserialize, Serialize};

use crate::messages::Events;

/// Running digest of a stream of events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EventDigest {
    /// Events seen.
    pub count: u64,
    /// Sum of x, pixels.
    pub sum_x: u64,
    /// Sum of y, pixels.
    pub sum_y: u64,
    /// ON events seen.
    pub on: u64,
    /// FNV-1a over (t bits, x, y, p) of every event in order.
    pub hash: u64,
}

impl Default for EventDigest {
    fn default() -> Self {
        Self {
            count: 0,
            sum_x: 0,
            sum_y: 0,
            on: 0,
            hash: 0xcbf2_9ce4_8422_2325,
        }
    }
}

impl EventDigest {
    /// Adds `events` in order.
    pub fn add(&mut self, events: &Events) {
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        let mut h = self.hash;
        for i in 0..events.len() {
            let words = [
                events.t[i].to_bits(),
                events.x[i] as u64,
                events.y[i] as u64,
                events.p[i] as u64,
            ];
            for w in words {
                h = (h ^ w).wrapping_mul(PRIME);
            }
            self.sum_x += events.x[i] as u64;
            self.sum_y += events.y[i] as u64;
            self.on += (events.p[i] != 0) as u64;
        }
        self.hash = h;
        self.count += events.len() as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_and_duplicates_change_the_digest() {
        let mut a = Events::default();
        a.push(0.1, 1, 2, 1);
        a.push(0.2, 3, 4, 0);
        let mut b = Events::default();
        b.push(0.2, 3, 4, 0);
        b.push(0.1, 1, 2, 1);
        let (mut da, mut db, mut split) = (
            EventDigest::default(),
            EventDigest::default(),
            EventDigest::default(),
        );
        da.add(&a);
        db.add(&b);
        assert_ne!(da.hash, db.hash);
        assert_eq!((da.sum_x, da.sum_y, da.on, da.count), (4, 6, 1, 2));
        // Splitting a stream into chunks does not change the digest.
        let mut first = Events::default();
        first.extend_from(&a, 0..1);
        let mut second = Events::default();
        second.extend_from(&a, 1..2);
        split.add(&first);
        split.add(&second);
        assert_eq!(split, da);
        let mut dup = da;
        dup.add(&second);
        assert_ne!(dup, da);
    }
}
