//! `evseg`: check and run graphs of evseg nodes.

mod ab;
mod bench_pipeline;
mod bench_scenes;
mod bench_sim;
mod bench_transport;
mod export;
mod info;
mod peers;
mod record;
mod replay;
mod resolve;
mod run;
mod rundir;
mod shm_limit;
mod spread;
mod supervise;
mod view;
mod watchdog;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Motion segmentation and egomotion from event-based normal flow, as a graph of processes.
#[derive(Parser)]
#[command(name = "evseg", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Run a graph: start a Zenoh router and this machine's nodes, watch them, report.
    Run {
        /// Graph file.
        #[arg(default_value = "graph.yaml")]
        graph: PathBuf,
        /// Start only the nodes assigned to this machine (and use its endpoints).
        #[arg(long)]
        machine: Option<String>,
        /// Instance name (part of every key); default: the graph's `name`.
        #[arg(long)]
        instance: Option<String>,
        /// Run folder; default: a new folder under runs/.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Router listen endpoint, replacing the machine's (repeatable), e.g. tcp/127.0.0.1:7450.
        #[arg(long)]
        listen: Vec<String>,
        /// Router endpoint to connect to, replacing the machine's (repeatable).
        #[arg(long)]
        connect: Vec<String>,
        /// Parameter override `node.param=value` (repeatable; value is JSON or a plain string).
        #[arg(long)]
        set: Vec<String>,
        /// No progress display.
        #[arg(long, short)]
        quiet: bool,
        /// Record the graph's outputs (those of its `record:` section, else all) into this MCAP
        /// file (relative to the working folder).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Restart a node of this machine that has received nothing this many seconds after
        /// its producers began publishing (its subscriptions never reached them), or, in
        /// lock-step, has processed nothing twice this long after every producer of its inputs
        /// began publishing (one subscription never reached its producer); 0 = never.
        #[arg(long, default_value_t = watchdog::DEFAULT_STARTUP_S)]
        startup_timeout: f64,
        /// Stop a lock-step run (a live run: once its sources have finished) in which no node
        /// made progress for this many seconds, naming every node's counters; 0 = wait forever.
        #[arg(long, default_value_t = watchdog::DEFAULT_STALL_S)]
        stall_timeout: f64,
    },
    /// Replay a recording: the nodes downstream of `--from` run live, fed by the recorded
    /// outputs of `--from` and the nodes upstream of it (published on the same keys, with
    /// lock-step credits); in lock-step mode their results equal the recorded run's.
    Replay {
        /// MCAP file written by `evseg run --record`.
        recording: PathBuf,
        /// Graph file (its downstream part may differ from the recorded run's).
        #[arg(long, default_value = "graph.yaml")]
        graph: PathBuf,
        /// Replay point: this node and the nodes it depends on are replayed, not run.
        #[arg(long)]
        from: String,
        /// Playback speed relative to the recorded publish times (1 = as recorded); default:
        /// as fast as lock-step credits allow.
        #[arg(long)]
        speed: Option<f64>,
        /// Instance name (part of every key); default: the graph's `name`.
        #[arg(long)]
        instance: Option<String>,
        /// Run folder; default: a new folder under runs/.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Router listen endpoint, replacing the machine's (repeatable).
        #[arg(long)]
        listen: Vec<String>,
        /// Parameter override `node.param=value` (repeatable) for the live nodes.
        #[arg(long)]
        set: Vec<String>,
        /// No progress display.
        #[arg(long, short)]
        quiet: bool,
        /// Record this run's outputs (the replayed ones too) into this MCAP file.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Replay a recording with gaps (a live run's drops): only the slices every replayed
        /// channel holds, renumbered 0, 1, 2, ...; without it such a recording is refused.
        #[arg(long)]
        skip_gaps: bool,
    },
    /// Compare two variants of a graph on the same recordings: A as written, B with node
    /// binaries swapped and/or parameters changed; prints the evaluator's figures side by side
    /// with the differences and writes ab.md and ab.json.
    Ab {
        /// Graph file (variant A).
        #[arg(default_value = "graph.yaml")]
        graph: PathBuf,
        /// Recording to replay (repeatable; one sequence each), from `evseg run --record`.
        #[arg(long = "recording", required = true)]
        recordings: Vec<PathBuf>,
        /// Replay point (this node and its upstream are replayed in both variants).
        #[arg(long, default_value = "slicer")]
        from: String,
        /// Variant B: run this node with another binary, `node=binary` (repeatable). Parameters
        /// the new binary lacks are removed, and optional inputs fed by outputs it does not
        /// publish are left unwired, each with a note.
        #[arg(long)]
        swap: Vec<String>,
        /// Both variants: parameter override `node.param=value` (repeatable).
        #[arg(long)]
        set: Vec<String>,
        /// Variant B only: parameter override `node.param=value` (repeatable).
        #[arg(long = "set-b")]
        set_b: Vec<String>,
        /// Working folder (run folders, variant B's graph, ab.md, ab.json).
        #[arg(long, default_value = "runs/ab")]
        work: PathBuf,
        /// Variant A's router listen endpoint (repeatable; default a free loopback port); variant
        /// B's router listens on a free loopback port and connects to it.
        #[arg(long)]
        listen: Vec<String>,
        /// Replay recordings with gaps (a live run's drops) in both variants: only the slices
        /// every replayed channel holds, renumbered (as `evseg replay --skip-gaps`).
        #[arg(long)]
        skip_gaps: bool,
    },
    /// Describe a recording: channels, schemas, message counts, time span, metadata, and
    /// whether it is complete (a cut-off file is read up to its last complete chunk).
    Info {
        /// MCAP file written by `evseg run --record`.
        recording: PathBuf,
    },
    /// Export a recording as NumPy .npy files (per-event labels and flow, per-slice egomotion,
    /// tracks, metrics; README.txt lists the columns).
    Export {
        /// MCAP file written by `evseg run --record`.
        recording: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Turn a recording into a Rerun recording (.rrd): events coloured by segment, normal-flow
    /// direction and ground truth, track boxes with ids, egomotion and metrics as time series.
    /// Open the file with `rerun FILE.rrd`.
    View {
        /// MCAP file written by `evseg run --record`.
        recording: PathBuf,
        /// Output .rrd file; default: the recording's path with the extension .rrd.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Stream to a running viewer at this gRPC URL instead of writing a file, e.g.
        /// rerun+http://127.0.0.1:9876/proxy.
        #[arg(long)]
        connect: Option<String>,
        /// Most events drawn per slice and layer (default: the viewer's, 10000).
        #[arg(long)]
        max_points: Option<usize>,
    },
    /// Check a graph without starting anything: every error with file, line and column.
    Check {
        /// Graph file.
        #[arg(default_value = "graph.yaml")]
        graph: PathBuf,
    },
    /// Benchmarks (use --release binaries). Without a subcommand: the versioned simulator scene
    /// set through a graph, scored by its evaluator, as a table with mean values; with
    /// `--sequences`, EVIMO2 v2 sequence folders instead, one row each. Every run's router
    /// listens on a free loopback port, so benchmarks run beside other graphs.
    #[command(args_conflicts_with_subcommands = true)]
    Bench {
        #[command(subcommand)]
        what: Option<BenchWhat>,
        /// Graph to run (needs an evseg-source and an evseg-evaluator node) [default:
        /// graph.yaml, or graphs/evimo2.yaml with --sequences]
        #[arg(long)]
        graph: Option<PathBuf>,
        /// EVIMO2 v2 sequence folders, or folders holding them (up to four levels below, as
        /// the dataset's `<camera>/<category>/<split>/`), to bench instead of the simulator's
        /// scene set; a sequence that fails is reported and the others still run.
        #[arg(long, num_args = 1..)]
        sequences: Vec<PathBuf>,
        /// Parameter override `node.param=value` for every run (repeatable), e.g. to compare a
        /// setting on the whole set; named in the table's title. The bench's own settings (the
        /// source's input, the evaluator's sequence name) cannot be overridden.
        #[arg(long)]
        set: Vec<String>,
        /// Working folder (one run folder per scene).
        #[arg(long, default_value = "runs/bench")]
        work: PathBuf,
    },
    /// Simulate a scene and write it as an EVIMO2 v2 sequence folder.
    Sim {
        /// Scene preset.
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(evseg_source::synthetic::PRESET_NAMES))]
        scene: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Seed.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Length, seconds of sensor time (default: the preset's).
        #[arg(long)]
        seconds: Option<f64>,
        /// Scale of the sensor (same field of view): 0.540625 gives a 346 x 260 sensor like a
        /// DAVIS346, 2 a 1280 x 960 one; the presets are 640 x 480.
        #[arg(long, default_value_t = 1.0)]
        resolution_scale: f64,
        /// A simulator setting, NAME=VALUE (repeatable, applied in order), so that the sequence
        /// differs from the preset as another camera or simulator would: contrast, c_on, c_off,
        /// c_sigma, refractory_s, noise_rate_hz, hot_pixels, hot_pixel_rate_hz, gyro_noise_std,
        /// gyro_bias, texture_contrast, camera_motion, edge_supersampling (`evseg_sim::SETTINGS`).
        #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_sim_setting)]
        settings: Vec<(String, f64)>,
    },
}

/// `NAME=VALUE` of `evseg sim --set`: a known setting name and a number.
fn parse_sim_setting(s: &str) -> Result<(String, f64), String> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=VALUE, got `{s}`"))?;
    let name = name.trim();
    if !evseg_sim::SETTINGS.iter().any(|(n, _)| *n == name) {
        return Err(format!(
            "unknown setting `{name}`; known: {}",
            evseg_sim::setting_names()
        ));
    }
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("setting `{name}`: `{}` is not a number", value.trim()))?;
    Ok((name.to_string(), value))
}

#[derive(Subcommand)]
enum BenchWhat {
    /// End-to-end events per second of a whole graph in lock-step mode on a simulated sequence
    /// written beforehand (not timed), with each stage's share of the busy time.
    Pipeline {
        /// Graph to run (its evseg-source node reads the sequence folder).
        #[arg(long, default_value = "graphs/evimo2.yaml")]
        graph: PathBuf,
        /// Simulator preset.
        #[arg(long, default_value = "two-objects")]
        scene: String,
        /// Seed.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Seconds of sensor time.
        #[arg(long, default_value_t = 3.0)]
        seconds: f64,
        /// Working folder (the sequence and the run folder).
        #[arg(long, default_value = "runs/bench-pipeline")]
        work: PathBuf,
        /// Runs of the graph, one after the other; with more than one, each run's line and the
        /// median, lowest and highest rate are printed (a shared machine's speed drifts).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        runs: u32,
    },
    /// The built-in simulator's speed: sensor seconds per CPU second of its one thread for each
    /// preset (real time is 1.00), with the events per second of sensor time; runs interleaved.
    Sim(bench_sim::SimBenchOptions),
    /// Events per second through source -> slicer -> sink: three processes over Zenoh against
    /// the same stages in one process.
    Transport {
        /// Events per slice (comma separated).
        #[arg(long, value_delimiter = ',', default_values_t = [10_000u64, 100_000, 1_000_000])]
        slices: Vec<u64>,
        /// Working folder for graphs and runs.
        #[arg(long, default_value = "runs/bench-transport")]
        work: PathBuf,
        /// Also write the table as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// Prints a bench's table and writes it as `bench.md`, with `json` as `bench.json`, into `work`.
fn publish_table(work: &Path, md: &str, json: &serde_json::Value) -> anyhow::Result<()> {
    use anyhow::Context;
    println!("{md}");
    std::fs::create_dir_all(work).with_context(|| format!("cannot create {}", work.display()))?;
    for (name, text) in [
        ("bench.md", md.to_string()),
        ("bench.json", serde_json::to_string_pretty(json)?),
    ] {
        let path = work.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn check(graph: &Path) -> anyhow::Result<()> {
    let dir = graph.parent().map(Path::to_path_buf).unwrap_or_default();
    let resolver = resolve::BinaryResolver::new(&dir);
    let g = run::load_graph(graph, &resolver)?;
    let edges: usize = g.nodes.iter().map(|n| n.inputs.len()).sum();
    println!(
        "{}: ok — instance `{}`, {} nodes, {edges} connections, {} mode, machines {:?}",
        graph.display(),
        g.name,
        g.nodes.len(),
        g.mode.as_str(),
        g.machines.iter().map(|m| m.name.as_str()).collect::<Vec<_>>()
    );
    // What `evseg run` would do about shared memory on this machine, for each machine's nodes
    // (run there as this user).
    for m in &g.machines {
        let nodes: Vec<_> = g.nodes_on(&m.name).into_iter().cloned().collect();
        if let Some(why) = shm_limit::over_limit(&nodes, &g.shared_memory, graph) {
            println!(
                "warning: on machine `{}` as this user, `evseg run` turns shared memory off: {why}",
                m.name
            );
        }
    }
    Ok(())
}

/// For commands that only read and write files and print: a standard output closed by its
/// reader (`evseg info rec.mcap | head`) ends the process quietly, as it ends a Unix tool, instead
/// of a panic at the next print. Rust ignores SIGPIPE so that writes to a closed pipe or socket
/// fail as errors; commands with network connections or child processes keep that.
fn end_quietly_when_stdout_closes() {
    #[cfg(unix)]
    // SAFETY: restores the default disposition of one signal, before any thread of this process
    // is started by the command.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> ExitCode {
    // Same allocator settings as the nodes (the in-process side of `bench transport` runs here).
    evseg_runtime::memory::tune_allocator();
    init_tracing();
    let cli = Cli::parse();
    let command = cli.command.unwrap_or(Command::Run {
        graph: PathBuf::from("graph.yaml"),
        machine: None,
        instance: None,
        out: None,
        listen: vec![],
        connect: vec![],
        set: vec![],
        quiet: false,
        record: None,
        startup_timeout: watchdog::DEFAULT_STARTUP_S,
        stall_timeout: watchdog::DEFAULT_STALL_S,
    });
    let offline = match &command {
        Command::Check { .. } | Command::Info { .. } | Command::Export { .. } | Command::Sim { .. } => true,
        Command::View { connect, .. } => connect.is_none(),
        _ => false,
    };
    if offline {
        end_quietly_when_stdout_closes();
    }
    let result = match command {
        Command::Check { graph } => check(&graph),
        Command::Info { recording } => info::info(&recording).map(|text| print!("{text}")),
        Command::Export { recording, out } => export::export(&recording, &out).map(|text| println!("{text}")),
        Command::View {
            recording,
            out,
            connect,
            max_points,
        } => {
            let sink = view::sink(&recording, out, connect);
            view::view(&recording, &sink, max_points).map(|text| println!("{text}"))
        }
        Command::Sim {
            scene,
            out,
            seed,
            seconds,
            resolution_scale,
            settings,
        } => evseg_source::synthetic::scene_config(&scene, seed, seconds, &settings)
            .and_then(|config| evseg_source::synthetic::write_evimo2_config(config, resolution_scale, &out))
            .map(|n| {
                let with: Vec<String> = settings.iter().map(|(k, v)| format!("{k}={v}")).collect();
                let with = if with.is_empty() {
                    String::new()
                } else {
                    format!(", {}", with.join(", "))
                };
                println!(
                    "{n} events of `{scene}` (seed {seed}{with}) written to {} as an EVIMO2 v2 folder",
                    out.display()
                );
            })
            .map_err(anyhow::Error::from),
        Command::Bench {
            what: None,
            graph,
            sequences,
            set,
            work,
        } if sequences.is_empty() => {
            let graph = graph.unwrap_or_else(|| PathBuf::from("graph.yaml"));
            bench_scenes::bench(&graph, &work, &set, false).and_then(|rows| {
                let md = bench_scenes::markdown(&rows, &graph, bench_scenes::Rows::Scenes, &set);
                publish_table(&work, &md, &serde_json::to_value(&rows)?)
            })
        }
        Command::Bench {
            what: None,
            graph,
            sequences,
            set,
            work,
        } => {
            let graph = graph.unwrap_or_else(|| PathBuf::from("graphs/evimo2.yaml"));
            bench_scenes::bench_sequences(&graph, &sequences, &work, &set, false).and_then(
                |(rows, failures)| {
                    let mut md = bench_scenes::markdown(&rows, &graph, bench_scenes::Rows::Sequences, &set);
                    md.push_str(&bench_scenes::failures_markdown(&failures));
                    let json = serde_json::json!({ "rows": rows, "failures": failures });
                    publish_table(&work, &md, &json)?;
                    if failures.is_empty() {
                        Ok(())
                    } else {
                        anyhow::bail!(
                            "{} of {} sequences failed: {}",
                            failures.len(),
                            failures.len() + rows.len(),
                            failures
                                .iter()
                                .map(|f| f.sequence.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    }
                },
            )
        }
        Command::Bench {
            what:
                Some(BenchWhat::Pipeline {
                    graph,
                    scene,
                    seed,
                    seconds,
                    work,
                    runs,
                }),
            ..
        } => bench_pipeline::run_and_write(
            &bench_pipeline::PipelineOptions {
                graph,
                scene,
                seed,
                seconds,
                work,
            },
            runs,
        ),
        Command::Bench {
            what: Some(BenchWhat::Sim(options)),
            ..
        } => bench_sim::bench(&options).and_then(|b| {
            publish_table(
                &options.work,
                &bench_sim::markdown(&b),
                &serde_json::to_value(&b)?,
            )
        }),
        Command::Bench {
            what: Some(BenchWhat::Transport { slices, work, json }),
            ..
        } => bench_transport::bench(&slices, &work).and_then(|rows| {
            println!("{}", bench_transport::markdown(&rows));
            if let Some(p) = json {
                std::fs::write(&p, serde_json::to_string_pretty(&rows)?)?;
            }
            Ok(())
        }),
        Command::Run {
            graph,
            machine,
            instance,
            out,
            listen,
            connect,
            set,
            quiet,
            record,
            startup_timeout,
            stall_timeout,
        } => watchdog::WatchdogSettings::from_seconds(startup_timeout, stall_timeout).and_then(|watchdog| {
            let opts = run::RunOptions {
                graph,
                machine,
                instance,
                out,
                listen,
                connect,
                set,
                quiet,
                record,
                replay: None,
                watchdog,
            };
            run::run(&opts).map(|outcome| print_outcome(&outcome))
        }),
        Command::Ab {
            graph,
            recordings,
            from,
            swap,
            set,
            set_b,
            work,
            listen,
            skip_gaps,
        } => {
            let o = ab::AbOptions {
                graph,
                recordings,
                from,
                swap,
                set,
                set_b,
                work,
                listen,
                skip_gaps,
            };
            ab::ab(&o).and_then(|rows| {
                let md = ab::markdown(&rows, &o);
                println!("{md}");
                std::fs::write(o.work.join("ab.md"), &md)?;
                std::fs::write(o.work.join("ab.json"), serde_json::to_string_pretty(&rows)?)?;
                Ok(())
            })
        }
        Command::Replay {
            recording,
            graph,
            from,
            speed,
            instance,
            out,
            listen,
            set,
            quiet,
            record,
            skip_gaps,
        } => {
            if let Err(e) = replay::check_record_target(&recording, record.as_deref()) {
                print_error(&e);
                return ExitCode::FAILURE;
            }
            let opts = run::RunOptions {
                graph,
                instance,
                out,
                listen,
                set,
                quiet,
                record,
                replay: Some(replay::ReplaySpec {
                    recording,
                    from,
                    speed,
                    skip_gaps,
                }),
                ..run::RunOptions::default()
            };
            run::run(&opts).map(|outcome| print_outcome(&outcome))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            print_error(&e);
            ExitCode::FAILURE
        }
    }
}

/// Prints `e` on stderr as `error: ...` with its causes, except a graph file's errors: its
/// diagnostics already read `file:line:column: error: ...` (one per line, the form editors jump
/// to), and its other errors name their cause in their own message.
fn print_error(e: &anyhow::Error) {
    eprintln!("{}", error_text(e));
}

/// The text [`print_error`] prints.
fn error_text(e: &anyhow::Error) -> String {
    use evseg_graph::GraphError;
    match e.downcast_ref::<GraphError>() {
        // Only when nothing was added on top (a context would be lost).
        Some(g) if e.to_string() == g.to_string() => match g {
            GraphError::Invalid(_) => g.to_string(),
            _ => format!("error: {g}"),
        },
        _ => format!("error: {e:#}"),
    }
}

/// Prints a finished run: the per-node table, the nodes' reports, where it was recorded, how long it took.
fn print_outcome(outcome: &run::RunOutcome) {
    let order: Vec<String> = outcome.stats.keys().cloned().collect();
    println!("{}", run::summary(outcome, &order));
    for report in run::reports(&outcome.dir) {
        if let Ok(text) = std::fs::read_to_string(&report) {
            println!("{}:\n{text}", report.display());
        }
    }
    if let Some(table) = run::flow_comparison(&outcome.dir) {
        println!("{table}");
    }
    if let Some(path) = &outcome.recording {
        println!("recorded to {}", path.display());
    }
    for why in &outcome.restarts {
        println!("restarted during the run: {why}");
    }
    let problems = run::problem_lines(&outcome.dir, true);
    if !problems.is_empty() {
        println!(
            "logged at WARN or ERROR (the whole lines in {}):",
            outcome.dir.join("logs").display()
        );
        for line in problems {
            println!("  {line}");
        }
    }
    println!(
        "run finished in {:.2} s; folder {}",
        outcome.seconds,
        outcome.dir.display()
    );
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use evseg_graph::{Diagnostic, GraphError, Span};

    use super::{Cli, Command, error_text};

    #[test]
    fn errors_print_once_with_their_causes_and_diagnostics_in_compiler_form() {
        let d = |line| Diagnostic::new("g.yaml", Span::new(line, 3), "bad");
        let invalid = anyhow::Error::from(GraphError::Invalid(vec![d(2), d(5)]));
        assert_eq!(
            error_text(&invalid),
            "g.yaml:2:3: error: bad\ng.yaml:5:3: error: bad"
        );
        let io = anyhow::Error::from(GraphError::Io {
            file: "g.yaml".into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "gone"),
        });
        assert_eq!(error_text(&io), "error: cannot read graph file g.yaml: gone");
        let wrapped = anyhow::Error::from(GraphError::Invalid(vec![d(2)])).context("replay");
        assert_eq!(error_text(&wrapped), "error: replay: g.yaml:2:3: error: bad");
        assert_eq!(error_text(&anyhow::anyhow!("plain")), "error: plain");
    }

    #[test]
    fn sim_takes_every_preset_and_refuses_an_unknown_scene_naming_the_presets() {
        for &scene in evseg_source::synthetic::PRESET_NAMES {
            let cli = Cli::try_parse_from(["evseg", "sim", "--scene", scene, "--out", "/tmp/x"]);
            assert!(
                matches!(cli.map(|c| c.command), Ok(Some(Command::Sim { .. }))),
                "{scene}"
            );
        }
        let err = Cli::try_parse_from(["evseg", "sim", "--scene", "three-object", "--out", "/tmp/x"])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("three-object") && err.contains("three-objects") && err.contains("camera-only"),
            "{err}"
        );
    }

    #[test]
    fn sim_settings_are_name_value_pairs_of_known_settings() {
        let args = |extra: &[&'static str]| {
            let mut a = vec!["evseg", "sim", "--scene", "one-object", "--out", "/tmp/x"];
            a.extend_from_slice(extra);
            Cli::try_parse_from(a)
        };
        let cli = args(&["--set", "contrast=0.3", "--set", " noise_rate_hz = 1 "]);
        let Ok(Cli {
            command: Some(Command::Sim { settings, .. }),
        }) = cli
        else {
            panic!("not parsed");
        };
        assert_eq!(
            settings,
            [("contrast".to_string(), 0.3), ("noise_rate_hz".to_string(), 1.0)]
        );
        for (bad, says) in [
            ("contrast", "NAME=VALUE"),
            ("thresh=0.3", "unknown setting `thresh`"),
            ("contrast=high", "`high` is not a number"),
        ] {
            let err = args(&["--set", bad])
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }

    #[test]
    fn bench_sim_takes_a_list_of_presets_and_refuses_an_unknown_one_or_no_runs() {
        let cli = Cli::try_parse_from(["evseg", "bench", "sim", "--scenes", "one-object,two-objects"]);
        let Ok(Cli {
            command:
                Some(Command::Bench {
                    what: Some(super::BenchWhat::Sim(o)),
                    ..
                }),
        }) = cli
        else {
            panic!("not parsed");
        };
        assert_eq!(o.scenes, ["one-object", "two-objects"]);
        assert_eq!((o.runs, o.seconds, o.seed), (3, 3.0, 1));
        for (bad, says) in [
            (["--scenes", "one-object,nope"], "nope"),
            (["--runs", "0"], "0"),
            (["--set", "thresh=1"], "unknown setting `thresh`"),
        ] {
            let mut a = vec!["evseg", "bench", "sim"];
            a.extend_from_slice(&bad);
            let err = Cli::try_parse_from(a)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains(says), "{bad:?}: {err}");
        }
    }
}
