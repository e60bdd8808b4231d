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

#[cfg(test)]
mod tests {
    use super::*;

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
