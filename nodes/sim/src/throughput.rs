//! Timing the simulator: how many seconds of sensor time it produces per second of its own
//! thread's CPU time (the figure of issue 3's real-time requirement), measured the same way by
//! `evseg bench sim`, the `sim_stats` example and anyone timing a configuration of their own.

use std::time::Instant;

use crate::{SceneConfig, SimChunk, SimError, Simulator};

/// Sensor time per [`Simulator::next_chunk`] call while timing, s (the output does not depend
/// on it; 50 ms is the source node's default chunk).
pub const TIMING_CHUNK_S: f64 = 0.05;

/// CPU time the calling thread has run, s, from `/proc/thread-self/schedstat` (Linux); `None`
/// where that file cannot be read. Thread CPU time is steadier than wall time on a shared
/// machine, since time the thread waits for a core is not counted.
pub fn thread_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

/// What one timed simulation produced and cost.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Timing {
    /// Sensor time simulated, s.
    pub simulated_s: f64,
    /// Events produced (model and noise).
    pub events: u64,
    /// Wall time of [`Simulator::new`] (texture baking, first key frame), s; not part of the
    /// rates below.
    pub setup_s: f64,
    /// Wall time of the simulation, s.
    pub wall_s: f64,
    /// CPU time of the simulating thread, s (`None` where [`thread_cpu_seconds`] is not
    /// available).
    pub cpu_s: Option<f64>,
}

impl Timing {
    /// Events per second of sensor time.
    pub fn events_per_sensor_s(&self) -> f64 {
        self.events as f64 / self.simulated_s
    }

    /// Sensor seconds per CPU second of the simulating thread (at least 1: real time on one
    /// core), or per wall second where CPU time is not available.
    pub fn realtime_factor(&self) -> f64 {
        self.simulated_s / self.cpu_s.unwrap_or(self.wall_s)
    }

    /// Events per CPU second of the simulating thread (per wall second where CPU time is not
    /// available).
    pub fn events_per_cpu_s(&self) -> f64 {
        self.events as f64 / self.cpu_s.unwrap_or(self.wall_s)
    }
}

/// Simulates the first `seconds` of `config` (at most its duration) in chunks of
/// [`TIMING_CHUNK_S`] and times it; `on_chunk` sees every chunk (its time is counted, so keep
/// it light).
pub fn time_simulation(
    config: SceneConfig,
    seconds: f64,
    mut on_chunk: impl FnMut(&SimChunk),
) -> Result<(Simulator, Timing), SimError> {
    if !(seconds.is_finite() && seconds > 0.0) {
        return Err(SimError::Config(format!(
            "seconds to time must be > 0, got {seconds}"
        )));
    }
    let t0 = Instant::now();
    let mut sim = Simulator::new(config)?;
    let setup_s = t0.elapsed().as_secs_f64();
    let end = seconds.min(sim.duration());
    let cpu0 = thread_cpu_seconds();
    let t1 = Instant::now();
    let (mut t, mut events) = (0.0, 0u64);
    while t < end - 1e-9 {
        t = (t + TIMING_CHUNK_S).min(end);
        let chunk = sim.next_chunk(t);
        events += chunk.events.len() as u64;
        on_chunk(&chunk);
    }
    let wall_s = t1.elapsed().as_secs_f64();
    let cpu_s = match (cpu0, thread_cpu_seconds()) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    Ok((
        sim,
        Timing {
            simulated_s: t,
            events,
            setup_s,
            wall_s,
            cpu_s,
        },
    ))
}

/// Iterations of [`reference_rate`]'s loop: about 0.25 s on a 2020s server core, so that the
/// thread CPU clock's granularity (a scheduler tick, 4 ms here) stays under 2 %.
const REFERENCE_ITERATIONS: u32 = 50_000_000;
/// Entries of [`reference_rate`]'s table (256 KiB of f32: in a core's L2 cache, as the
/// simulator's hot texture texels are).
const REFERENCE_TABLE: usize = 1 << 16;

/// This machine's speed at a fixed piece of work shaped like the simulator's inner loops (a
/// table lookup, a square root, a division, dependent float arithmetic), in million iterations
/// per CPU second of the calling thread (per wall second where thread CPU time is not
/// available). It does not depend on the simulator's code, so two benchmarks of the same code
/// at different hours can be compared: a shared host whose other tenants slow its cores slows
/// this figure as much as the simulator's.
pub fn reference_rate() -> f64 {
    let table: Vec<f32> = (0..REFERENCE_TABLE)
        .map(|i| 1.0 + (i % 97) as f32 * 0.01)
        .collect();
    let seconds = seconds_to_run(|| {
        let mut state = 0x9e37_79b9u32;
        let mut acc = 0.0f32;
        for _ in 0..REFERENCE_ITERATIONS {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let v = table[state as usize % REFERENCE_TABLE];
            acc = (acc * 0.5 + v.sqrt() / (v + acc.abs() + 1.0)).min(1e6);
        }
        std::hint::black_box(acc);
    });
    f64::from(REFERENCE_ITERATIONS) / seconds / 1e6
}

/// Seconds `work` takes: the calling thread's CPU time ([`thread_cpu_seconds`]), or wall time
/// where that is not available or did not advance; at least 1 ns (the references divide by it).
fn seconds_to_run(work: impl FnOnce()) -> f64 {
    let (cpu0, wall0) = (thread_cpu_seconds(), Instant::now());
    work();
    let seconds = match (cpu0, thread_cpu_seconds()) {
        (Some(a), Some(b)) if b > a => b - a,
        _ => wall0.elapsed().as_secs_f64(),
    };
    seconds.max(1e-9)
}

/// Bytes of [`reference_memory_gb_s`]'s buffer: 64 MiB, twice the L3 cache of this kind of
/// server, as the simulator's per-pixel arrays and key frames (about 23 MB) are streamed
/// through memory at every key frame.
const REFERENCE_BUFFER_BYTES: usize = 64 << 20;
/// Passes of [`reference_memory_gb_s`] over its buffer: about 0.15 s, so that the thread CPU
/// clock's granularity (4 ms here) stays under 3 %.
const REFERENCE_PASSES: usize = 48;

/// This machine's memory speed at the moment: GB per CPU second (per wall second where thread
/// CPU time is not available) of read-modify-write passes over a buffer larger than the
/// caches. [`reference_rate`] stays in a core's own cache, so a host whose other tenants take
/// the shared cache and memory slows the simulator without slowing it; this figure shows that
/// case.
pub fn reference_memory_gb_s() -> f64 {
    let mut buffer = vec![1.0f32; REFERENCE_BUFFER_BYTES / 4];
    let seconds = seconds_to_run(|| {
        for pass in 0..REFERENCE_PASSES {
            let k = 1.0 + pass as f32 * 1e-3;
            for v in &mut buffer {
                *v = *v * k + 1e-3;
            }
            std::hint::black_box(&mut buffer);
        }
    });
    // Each pass reads and writes the buffer.
    (2 * REFERENCE_PASSES * REFERENCE_BUFFER_BYTES) as f64 / seconds / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_rate_is_a_positive_finite_figure() {
        let r = reference_rate();
        assert!(r.is_finite() && r > 0.0, "{r}");
        let m = reference_memory_gb_s();
        assert!(m.is_finite() && m > 0.0, "{m}");
    }

    #[test]
    fn a_short_run_is_timed_and_counts_every_event() {
        let cfg = crate::preset("one-object", 3)
            .unwrap()
            .with_resolution_scale(0.125);
        let mut seen = 0u64;
        let (sim, timing) = time_simulation(cfg, 0.12, |c| seen += c.events.len() as u64).unwrap();
        assert!((timing.simulated_s - 0.12).abs() < 1e-12);
        assert!((sim.time() - 0.12).abs() < 1e-9);
        assert_eq!(timing.events, seen);
        assert!(timing.events > 0);
        assert!(timing.wall_s > 0.0 && timing.realtime_factor() > 0.0);
        assert!((timing.events_per_sensor_s() - seen as f64 / 0.12).abs() < 1e-6);
    }

    #[test]
    fn a_non_positive_duration_is_refused() {
        let cfg = crate::preset("one-object", 3).unwrap();
        for s in [0.0, -1.0, f64::NAN] {
            assert!(matches!(
                time_simulation(cfg.clone(), s, |_| {}),
                Err(SimError::Config(_))
            ));
        }
    }
}
