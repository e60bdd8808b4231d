//! Simulator -> slicer -> evaluator in one process, for three results:
//! - `baseline`: every event background, no egomotion (what `evseg-baseline` publishes);
//! - `oracle`: labels = the simulator's per-event object ids, direction = the true velocity of
//!   the slice (mean of its camera velocity samples). Per-event IoU must be 1 and direction
//!   error 0; the mask IoU measures what the paper's protocol itself loses on exact labels;
//! - `oracle-poses`: the same result, but the truth's velocity samples are removed so the
//!   evaluator derives the true velocity from poses (as on EVIMO2): its errors measure the
//!   pose-derived ground truth against the simulator's exact velocities.
//!
//! ```text
//! cargo run --release -p evseg-evaluator --example sim_report -- [preset] [seconds] [out_dir]
//! ```

use std::path::PathBuf;

use evseg_evaluator::report::{markdown, write_report};
use evseg_evaluator::{EvalParams, Evaluator, SliceInput};
use evseg_schemas::{Egomotion, EventPacket, Tracks, Truth};
use evseg_slicer::{SliceOut, Slicer, SlicerParams};

fn oracle(truth: &Truth, n: usize) -> Tracks {
    let v: Vec<[f64; 3]> = truth.camera.iter().filter_map(|c| c.linear_velocity).collect();
    let mean = v
        .iter()
        .fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    let valid = !v.is_empty() && mean.iter().any(|&x| x != 0.0);
    Tracks {
        label: if truth.event_object.len() == n {
            truth.event_object.iter().map(|&i| i as u32).collect()
        } else {
            vec![0; n]
        },
        tracks: vec![],
        egomotion: Egomotion {
            direction: mean,
            omega: [0.0; 3],
            valid,
        },
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("two-objects", |s| s.as_str());
    let seconds: f64 = args.get(1).map_or(Ok(1.0), |s| s.parse())?;
    let out = PathBuf::from(args.get(2).map_or("/tmp/evseg-sim-report", |s| s.as_str()));
    let mut cfg = evseg_sim::preset(name, 1)?;
    cfg.duration_s = cfg.duration_s.min(seconds);
    let mut sim = evseg_sim::Simulator::new(cfg)?;
    let camera = sim.camera_info();
    let mut slicer = Slicer::new(SlicerParams::default())?;
    let names = ["baseline", "oracle", "oracle-poses"];
    let mut evs: Vec<Evaluator> = names
        .iter()
        .map(|_| Evaluator::new(EvalParams::default()))
        .collect::<Result<_, _>>()?;
    let feed = |slices: Vec<SliceOut>, evs: &mut Vec<Evaluator>| -> Result<(), Box<dyn std::error::Error>> {
        for s in slices {
            let truth = s.truth.unwrap_or_default();
            let n = s.slice.events.len();
            let base = Tracks {
                label: vec![0; n],
                tracks: vec![],
                egomotion: Egomotion::default(),
            };
            let orc = oracle(&truth, n);
            let mut poses_only = truth.clone();
            for c in &mut poses_only.camera {
                c.linear_velocity = None;
            }
            for (ev, (t, r)) in evs
                .iter_mut()
                .zip([(&truth, &base), (&truth, &orc), (&poses_only, &orc)])
            {
                ev.push(SliceInput {
                    seq: s.seq,
                    t_start: s.t_start,
                    t_end: s.t_end,
                    slice: &s.slice,
                    truth: t,
                    result: r,
                })?;
            }
        }
        Ok(())
    };
    let t0 = std::time::Instant::now();
    while !sim.is_finished() {
        let t_end = sim.time() + 0.01;
        let chunk = sim.next_chunk(t_end);
        let packet = EventPacket {
            camera: camera.clone(),
            events: chunk.events,
            imu: chunk.imu,
        };
        let slices = slicer.push(packet, Some(chunk.truth), sim.time())?;
        feed(slices, &mut evs)?;
    }
    feed(slicer.finish(), &mut evs)?;
    eprintln!(
        "simulated {seconds} s of {name} in {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    let mut rows = Vec::new();
    for (ev, n) in evs.iter_mut().zip(names) {
        ev.finish()?;
        let label = format!("{name}/{n}");
        write_report(&out.join(n), ev, &label)?;
        rows.push(ev.summary(&label));
    }
    println!("{}", markdown::scoreboard_table(&rows));
    Ok(())
}
