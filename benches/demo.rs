//! `brdfd demo` end to end, as the README's main command runs it: the committed N9 reference
//! and eight sample recordings replayed (strict, accelerated) through the simulated
//! instruments, the driver tasks, the orchestrator and a SQLite file store, and the 8 × 3 fits
//! on the fit worker (one fit per core). Each run uses a fresh database in a temporary
//! directory. Prints, per run and as the median of the runs, the wall time and its split:
//! replay (first request to last reading), instruments measuring, store calls, fitting (fit
//! time summed over fits) — and checks the target of under 5 s wall.
//!
//! `cargo bench --bench demo` (release profile); `BRDFD_DEMO_RUNS=N` sets the number of runs
//! (default 5).

use std::time::Instant;

use brdfd::cli::demo::{DemoArgs, run_demo};
use brdfd::optimise::{Method, Settings};
use brdfd::store::Store;

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn main() {
    let runs: usize = std::env::var("BRDFD_DEMO_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut rows: Vec<[f64; 5]> = Vec::new();
    for run in 1..=runs {
        let dir = tempfile::tempdir().unwrap();
        let args = DemoArgs {
            dir: dir.path().to_path_buf(),
            method: Method::default(),
            seed: Settings::default().seed,
            jobs: None,
            bootstrap: 0,
            json: false,
        };
        let started = Instant::now();
        let result = rt.block_on(async {
            let store = Store::open(dir.path().join("brdfd.db")).await.unwrap();
            let r = run_demo(&store, &args).await.unwrap();
            store.close().await;
            r
        });
        let wall = started.elapsed().as_secs_f64();
        let row = [
            wall,
            result.outcome.replay_wall.as_secs_f64(),
            result.timings.acquire_s,
            result.timings.store_s,
            result.timings.fit_s,
        ];
        println!(
            "run {run}: wall {:.3} s = replay {:.3} s (instruments {:.3} s) + fits to finish; \
             store {:.3} s, fitting {:.3} s summed over {} thread(s)",
            row[0], row[1], row[2], row[3], row[4], result.jobs
        );
        rows.push(row);
    }
    let m = |k: usize| median(rows.iter().map(|r| r[k]).collect());
    println!(
        "demo, median of {runs}: wall {:.3} s; replay {:.3} s (instruments {:.3} s); store {:.3} s; \
         fit {:.3} s",
        m(0),
        m(1),
        m(2),
        m(3),
        m(4)
    );
    assert!(
        m(0) < 5.0,
        "the demo took {:.2} s, over the 5 s target",
        m(0)
    );
}
