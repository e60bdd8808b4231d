//! A test pattern: events at a fixed rate, spread over the sensor by a fixed pseudo-random
//! sequence, alternating polarity. It has no scene content; it exists to measure and test the
//! transport (throughput, exactly-once delivery) with a source that costs almost nothing.

use evseg_schemas::{CameraInfo, Events};

use crate::{Batch, EventSource, SourceError};

/// Test pattern settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatternParams {
    /// Events per second of sensor time.
    pub rate: f64,
    /// Length of the stream, seconds.
    pub seconds: f64,
    /// Sensor width, pixels.
    pub width: u16,
    /// Sensor height, pixels.
    pub height: u16,
    /// Seed of the pixel sequence.
    pub seed: u64,
}

/// The test-pattern source.
#[derive(Debug, Clone)]
pub struct Pattern {
    params: PatternParams,
    emitted: u64,
    total: u64,
    state: u64,
}

/// Highest rate of the pattern, events per second (100 M/s, above any sensor's sustained
/// rate; a 10 ms packet then holds a million events).
pub const MAX_RATE: f64 = 1e8;

impl Pattern {
    /// A pattern with `params`.
    pub fn new(params: PatternParams) -> Result<Self, SourceError> {
        if !(params.rate > 0.0 && params.rate <= MAX_RATE) {
            return Err(SourceError::Param(format!(
                "rate must be within 0..={MAX_RATE} events/s (> 0), got {}",
                params.rate
            )));
        }
        if !(params.seconds.is_finite() && params.seconds > 0.0) {
            return Err(SourceError::Param(format!(
                "seconds must be > 0, got {}",
                params.seconds
            )));
        }
        if params.width == 0 || params.height == 0 {
            return Err(SourceError::Param("width and height must be > 0".into()));
        }
        let total = (params.rate * params.seconds).floor() as u64;
        Ok(Self {
            params,
            emitted: 0,
            total,
            state: params.seed ^ 0x9e37_79b9_7f4a_7c15,
        })
    }

    fn next_u32(&mut self) -> u32 {
        // xorshift64*: fast and deterministic.
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        (self.state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 32) as u32
    }
}

impl EventSource for Pattern {
    fn camera(&self) -> CameraInfo {
        let (w, h) = (self.params.width, self.params.height);
        CameraInfo::pinhole(w, h, f64::from(w), "test-pattern")
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        if self.emitted >= self.total {
            return Ok(None);
        }
        // Event i fires at i / rate; take exactly the events with i / rate < t_end (the
        // product t_end * rate alone can round across an integer).
        let rate = self.params.rate;
        let mut upto = ((t_end * rate).ceil().max(0.0) as u64).min(self.total);
        while upto < self.total && (upto as f64 / rate) < t_end {
            upto += 1;
        }
        while upto > self.emitted && ((upto - 1) as f64 / rate) >= t_end {
            upto -= 1;
        }
        let n = upto.saturating_sub(self.emitted) as usize;
        let mut events = Events::with_capacity(n);
        let (w, h) = (self.params.width as u32, self.params.height as u32);
        for i in self.emitted..upto {
            let r = self.next_u32();
            events.push(
                i as f64 / self.params.rate,
                (r % w) as u16,
                ((r >> 16) % h) as u16,
                (i & 1) as u8,
            );
        }
        self.emitted = upto;
        Ok(Some(Batch {
            events,
            imu: Vec::new(),
            truth: None,
        }))
    }

    fn has_truth(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> PatternParams {
        PatternParams {
            rate: 1000.0,
            seconds: 1.0,
            width: 64,
            height: 48,
            seed: 1,
        }
    }

    #[test]
    fn emits_exactly_rate_times_seconds_in_order() {
        let mut p = Pattern::new(params()).unwrap();
        let mut n = 0;
        let mut last = -1.0;
        let mut k = 1;
        while let Some(b) = p.next_batch(k as f64 * 0.013).unwrap() {
            for (&t, &x) in b.events.t.iter().zip(&b.events.x) {
                assert!(t > last && t < k as f64 * 0.013 && x < 64);
                last = t;
            }
            n += b.events.len();
            k += 1;
        }
        assert_eq!(n, 1000);
    }

    #[test]
    fn batches_hold_exactly_the_events_before_their_end() {
        // 0.01 * 70 rounds to 0.7000000000000001, whose product with the rate rounds to an
        // integer: the event at exactly 0.7 s belongs to that batch.
        let mut p = Pattern::new(PatternParams {
            rate: 200_000.0,
            seconds: 1.0,
            ..params()
        })
        .unwrap();
        let mut k = 0u64;
        while let Some(b) = p.next_batch(k as f64 * 0.01 + 0.01).unwrap() {
            let t_end = k as f64 * 0.01 + 0.01;
            assert!(b.events.t.iter().all(|&t| t < t_end));
            k += 1;
            let next = p.clone().next_batch(k as f64 * 0.01 + 0.01).unwrap();
            if let Some(n) = next {
                assert!(
                    n.events.t.iter().all(|&t| t >= t_end),
                    "batch {k} starts before {t_end}"
                );
            }
        }
    }

    #[test]
    fn bad_params_are_refused() {
        for rate in [0.0, f64::NAN, 1e15] {
            let e = Pattern::new(PatternParams { rate, ..params() })
                .err()
                .map(|e| e.to_string());
            assert!(e.is_some_and(|e| e.contains("rate must be within")), "{rate}");
        }
        assert!(
            Pattern::new(PatternParams {
                seconds: f64::NAN,
                ..params()
            })
            .is_err()
        );
        assert!(Pattern::new(PatternParams { width: 0, ..params() }).is_err());
    }
}
