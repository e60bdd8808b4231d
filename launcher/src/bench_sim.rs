//! `evseg bench sim`: the built-in simulator's speed, in seconds of sensor time per CPU second
//! of the one thread that simulates (issue 3's requirement: real time on one core at 640 x 480
//! and about 1 M events per second of sensor time).
//!
//! Each preset runs from a fresh simulator for the given sensor time, timed by
//! [`evseg_sim::throughput::time_simulation`] (texture baking and the first key frame are
//! reported apart, not counted). With several runs they are interleaved (every preset once, then
//! again), so that a shared machine's drift spreads over all presets alike, and each preset's
//! median, lowest and highest factor are given.

use std::path::PathBuf;

use anyhow::Context;
use evseg_sim::throughput::{Timing, reference_memory_gb_s, reference_rate, time_simulation};

use crate::spread::median_and_range;

/// Shortest sensor time per run, s: one render chunk of the simulator is 50 ms, and a run much
/// shorter than that times start-up, not simulation.
pub const MIN_SECONDS: f64 = 0.05;

/// What to time (the options of `evseg bench sim`).
#[derive(Debug, Clone, clap::Args)]
pub struct SimBenchOptions {
    /// Presets (comma separated; default: every preset), in table order.
    #[arg(long, value_delimiter = ',', value_parser = clap::builder::PossibleValuesParser::new(evseg_source::synthetic::PRESET_NAMES))]
    pub scenes: Vec<String>,
    /// Seconds of sensor time per run.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Scene seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Runs of every preset (the median, lowest and highest are given).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub runs: u32,
    /// A simulator setting, NAME=VALUE, for every preset (as `evseg sim --set`).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = crate::parse_sim_setting)]
    pub settings: Vec<(String, f64)>,
    /// Working folder (bench.md, bench.json).
    #[arg(long, default_value = "runs/bench-sim")]
    pub work: PathBuf,
}

/// One preset's runs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SimBenchRow {
    /// Preset name.
    pub scene: String,
    /// Sensor size, px.
    pub width: u16,
    /// Sensor size, px.
    pub height: u16,
    /// Every run, in the order run.
    pub runs: Vec<Timing>,
}

impl SimBenchRow {
    /// Events per second of sensor time (the same in every run: the output is deterministic).
    pub fn events_per_sensor_s(&self) -> f64 {
        self.runs.first().map_or(0.0, Timing::events_per_sensor_s)
    }

    /// Median, lowest and highest sensor seconds per CPU second over the runs.
    pub fn realtime(&self) -> Option<(f64, f64, f64)> {
        let f: Vec<f64> = self.runs.iter().map(Timing::realtime_factor).collect();
        median_and_range(&f)
    }

    /// Median events per CPU second over the runs.
    pub fn events_per_cpu_s(&self) -> Option<f64> {
        let f: Vec<f64> = self.runs.iter().map(Timing::events_per_cpu_s).collect();
        median_and_range(&f).map(|m| m.0)
    }
}

/// The whole benchmark, as written to `bench.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SimBench {
    /// Sensor time per run, s.
    pub seconds: f64,
    /// Scene seed.
    pub seed: u64,
    /// Simulator settings applied to every preset.
    pub settings: Vec<(String, f64)>,
    /// The processor (`model name` of `/proc/cpuinfo`, or "unknown").
    pub cpu: String,
    /// Logical processors of the machine (the benchmark uses one).
    pub logical_cpus: usize,
    /// True when thread CPU time was measured (Linux); otherwise the factors are per wall second.
    pub cpu_time: bool,
    /// One row per preset.
    pub rows: Vec<SimBenchRow>,
    /// [`reference_rate`] before every run, in the order run (million iterations per CPU
    /// second): the machine's own speed at that moment, to compare benchmarks of different
    /// hours.
    pub reference_m_per_s: Vec<f64>,
    /// [`reference_memory_gb_s`] before every run, in the order run (GB per CPU second): the
    /// memory's speed at that moment, which the simulator's key frames depend on and the
    /// in-cache reference does not see.
    pub memory_gb_per_s: Vec<f64>,
}

/// The processor's model name, from `/proc/cpuinfo` (Linux), or "unknown".
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".to_string())
}

/// Runs the benchmark, printing each run's line to standard error as it ends.
pub fn bench(options: &SimBenchOptions) -> anyhow::Result<SimBench> {
    // Shorter runs time nothing but the first chunk's set-up (and 0 events give no rate).
    if options.seconds.is_nan() || options.seconds < MIN_SECONDS {
        anyhow::bail!("--seconds {} must be at least {MIN_SECONDS}", options.seconds);
    }
    let scenes: Vec<String> = if options.scenes.is_empty() {
        evseg_source::synthetic::PRESET_NAMES
            .iter()
            .map(|s| s.to_string())
            .collect()
    } else {
        options.scenes.clone()
    };
    let mut rows: Vec<SimBenchRow> = Vec::with_capacity(scenes.len());
    // Each preset's configuration, checked once and cloned for every run.
    let mut configs = Vec::with_capacity(scenes.len());
    for scene in &scenes {
        let cfg = evseg_source::synthetic::scene_config(
            scene,
            options.seed,
            Some(options.seconds),
            &options.settings,
        )
        .with_context(|| format!("preset `{scene}`"))?;
        cfg.validate()
            .with_context(|| format!("preset `{scene}` with the settings given"))?;
        rows.push(SimBenchRow {
            scene: scene.clone(),
            width: cfg.camera.width,
            height: cfg.camera.height,
            runs: Vec::new(),
        });
        configs.push(cfg);
    }
    // The table is written there at the end: a folder that cannot be made fails now, not after
    // every run.
    std::fs::create_dir_all(&options.work)
        .with_context(|| format!("cannot create the working folder {}", options.work.display()))?;
    let (mut reference_m_per_s, mut memory_gb_per_s) = (Vec::new(), Vec::new());
    for run in 1..=options.runs {
        for (row, cfg) in rows.iter_mut().zip(&configs) {
            reference_m_per_s.push(reference_rate());
            memory_gb_per_s.push(reference_memory_gb_s());
            let (_, timing) = time_simulation(cfg.clone(), options.seconds, |_| {})
                .with_context(|| format!("simulating preset `{}`", row.scene))?;
            eprintln!(
                "run {run}/{}: {:<15} {:.2} M events/s of sensor time, {:.3} sensor-s per {}-s (setup {:.2} s)",
                options.runs,
                row.scene,
                timing.events_per_sensor_s() / 1e6,
                timing.realtime_factor(),
                if timing.cpu_s.is_some() { "CPU" } else { "wall" },
                timing.setup_s
            );
            row.runs.push(timing);
        }
    }
    let cpu_time = rows.iter().flat_map(|r| &r.runs).all(|t| t.cpu_s.is_some());
    Ok(SimBench {
        seconds: options.seconds,
        seed: options.seed,
        settings: options.settings.clone(),
        cpu: cpu_model(),
        logical_cpus: std::thread::available_parallelism().map_or(1, usize::from),
        cpu_time,
        rows,
        reference_m_per_s,
        memory_gb_per_s,
    })
}

/// The table (Markdown) with its title and the requirement it is measured against.
pub fn markdown(b: &SimBench) -> String {
    let per = if b.cpu_time { "CPU" } else { "wall" };
    let runs = b.rows.first().map_or(0, |r| r.runs.len());
    let settings = if b.settings.is_empty() {
        String::new()
    } else {
        let s: Vec<String> = b.settings.iter().map(|(k, v)| format!("{k}={v}")).collect();
        format!(", settings {}", s.join(", "))
    };
    let mut out = format!(
        "Simulator speed: {:.2} s of sensor time per preset (seed {}{settings}), {runs} run(s) each, \
         interleaved; one thread on {} ({} logical CPUs). Sensor seconds per {per} second of the \
         simulating thread; texture baking and the first key frame are not counted.\n\
         Requirement (issue 3): at 640 x 480 and about 1 M events per second of sensor time, at \
         least 1.00 (real time) on one core.\n\n",
        b.seconds, b.seed, b.cpu, b.logical_cpus
    );
    if let (Some((median, lo, hi)), Some((mm, mlo, mhi))) = (
        median_and_range(&b.reference_m_per_s),
        median_and_range(&b.memory_gb_per_s),
    ) {
        out.push_str(&format!(
            "Machine references before each run, independent of the simulator's code (compare \
             benchmarks of different hours by them): a loop shaped like the simulator's, in a \
             core's cache (`evseg_sim::throughput::reference_rate`), {median:.1} M iterations per \
             {per}-s, median ({lo:.1}-{hi:.1}); passes over 64 MiB of memory \
             (`reference_memory_gb_s`), {mm:.2} GB per {per}-s ({mlo:.2}-{mhi:.2}).\n\n"
        ));
    }
    out.push_str(&format!(
        "| preset | sensor | M events / sensor-s | sensor-s per {per}-s, median | lowest | highest | M events per {per}-s | real time |\n"
    ));
    out.push_str("|---|---|---:|---:|---:|---:|---:|---|\n");
    for r in &b.rows {
        let Some((median, lo, hi)) = r.realtime() else {
            continue;
        };
        out.push_str(&format!(
            "| {} | {} x {} | {:.2} | {median:.3} | {lo:.3} | {hi:.3} | {:.2} | {} |\n",
            r.scene,
            r.width,
            r.height,
            r.events_per_sensor_s() / 1e6,
            r.events_per_cpu_s().unwrap_or(0.0) / 1e6,
            if median >= 1.0 { "yes" } else { "no" }
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timing(events: u64, cpu: f64) -> Timing {
        Timing {
            simulated_s: 2.0,
            events,
            setup_s: 0.1,
            wall_s: cpu + 0.01,
            cpu_s: Some(cpu),
        }
    }

    #[test]
    fn the_table_gives_each_presets_median_range_and_verdict() {
        let b = SimBench {
            seconds: 2.0,
            seed: 1,
            settings: vec![("contrast".into(), 0.3)],
            cpu: "Test CPU".into(),
            logical_cpus: 2,
            cpu_time: true,
            rows: vec![
                SimBenchRow {
                    scene: "fast".into(),
                    width: 640,
                    height: 480,
                    runs: vec![
                        timing(2_000_000, 1.0),
                        timing(2_000_000, 1.6),
                        timing(2_000_000, 2.5),
                    ],
                },
                SimBenchRow {
                    scene: "slow".into(),
                    width: 640,
                    height: 480,
                    runs: vec![timing(4_000_000, 2.5), timing(4_000_000, 4.0)],
                },
            ],
            reference_m_per_s: vec![80.0, 100.0, 90.0, 70.0, 95.0],
            memory_gb_per_s: vec![9.0, 10.0, 11.0, 8.0, 12.0],
        };
        let md = markdown(&b);
        assert!(
            md.contains("90.0 M iterations per CPU-s, median (70.0-100.0)"),
            "{md}"
        );
        assert!(md.contains("10.00 GB per CPU-s (8.00-12.00)"), "{md}");
        assert!(md.contains("settings contrast=0.3"), "{md}");
        assert!(md.contains("Test CPU (2 logical CPUs)"), "{md}");
        // 2 s in 1.6 s of CPU is 1.25; lowest 2 / 2.5, highest 2 / 1.0; 2 M events per 1.6 s.
        assert!(
            md.contains("| fast | 640 x 480 | 1.00 | 1.250 | 0.800 | 2.000 | 1.25 | yes |"),
            "{md}"
        );
        // Two runs: the median is the mean of 2 / 2.5 and 2 / 4.
        assert!(
            md.contains("| slow | 640 x 480 | 2.00 | 0.650 | 0.500 | 0.800 | 1.30 | no |"),
            "{md}"
        );
    }

    #[test]
    fn an_unknown_preset_or_setting_is_refused_before_any_run() {
        let mut o = SimBenchOptions {
            scenes: vec!["one-object".into(), "no-such-scene".into()],
            seconds: 0.05,
            seed: 1,
            runs: 1,
            settings: Vec::new(),
            work: tempfile::tempdir().unwrap().path().join("never-made"),
        };
        let e = format!("{:#}", bench(&o).unwrap_err());
        assert!(e.contains("no-such-scene"), "{e}");
        o.scenes = vec!["one-object".into()];
        o.settings = vec![("contrast".into(), -1.0)];
        let e = format!("{:#}", bench(&o).unwrap_err());
        assert!(
            e.contains("preset `one-object`")
                && e.contains("setting contrast = -1")
                && e.contains("c_on = -1"),
            "{e}"
        );
        o.settings.clear();
        for seconds in [f64::NAN, 1e-9] {
            o.seconds = seconds;
            let e = format!("{:#}", bench(&o).unwrap_err());
            assert!(e.contains("must be at least 0.05"), "{e}");
        }
        o.seconds = 0.05;
        let file = tempfile::NamedTempFile::new().unwrap();
        o.work = file.path().join("sub");
        let e = format!("{:#}", bench(&o).unwrap_err());
        assert!(
            e.contains("cannot create the working folder") && e.contains("sub"),
            "{e}"
        );
    }
}
