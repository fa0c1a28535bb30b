//! Store write latency on a real SQLite file (WAL, synchronous = NORMAL) in a temporary
//! directory: one reading committed on its own, as the acquisition path does, and one scan's 14
//! readings in one transaction, as an import does.
//!
//! Criterion reports mean and median; the tail matters for acquisition (a slow commit delays
//! the next reading), so a plain timed loop first prints p50 / p99 / max per operation.
//!
//! Run: `cargo bench --bench store`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};

use brdfd::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry};
use brdfd::store::{NewReading, ReadingValues, ReferenceId, ScanId, Store};

/// Reply frames about the size of the instruments' (31 f64 plus framing; one intensity).
fn frame(g: &Geometry) -> Vec<u8> {
    vec![0xA5; if g.device == Device::MaT12 { 264 } else { 24 }]
}

fn values(g: &Geometry, k: u64) -> ReadingValues {
    let x = (k % 1000) as f64 / 1000.0;
    match g.device {
        Device::MaT12 => ReadingValues::Spectrum(std::array::from_fn(|b| x + b as f64 * 1e-3)),
        Device::Sra => ReadingValues::Intensity(3.0 + x),
    }
}

async fn reference(store: &Store) -> ReferenceId {
    let id = store.begin_reference("Munsell N9", None).await.unwrap();
    for g in &GEOMETRIES {
        let v = match g.device {
            Device::MaT12 => ReadingValues::Spectrum([0.77; 31]),
            Device::Sra => ReadingValues::Intensity(0.245),
        };
        store
            .add_reference_reading(id, g.device, g, &v, &frame(g))
            .await
            .unwrap();
    }
    store.complete_reference(id).await.unwrap();
    id
}

async fn measuring_scans(store: &Store, reference: ReferenceId, n: u64) -> Vec<ScanId> {
    let mut scans = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let scan = store.request_scan("bench sample", reference).await.unwrap();
        store.start_measuring(scan).await.unwrap();
        scans.push(scan);
    }
    scans
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

/// The 14 readings of scan `k`, each with its geometry's frame from `frames`.
fn readings(frames: &[Vec<u8>], k: u64) -> Vec<NewReading<'_>> {
    GEOMETRIES
        .iter()
        .map(|g| NewReading {
            device: g.device,
            geometry: g,
            values: values(g, k),
            raw_frame: &frames[g.index],
        })
        .collect()
}

fn report(what: &str, mut t: Vec<Duration>) {
    t.sort_unstable();
    let mean = t.iter().sum::<Duration>() / t.len() as u32;
    println!(
        "{what}: n = {}, p50 = {:.1} µs, p99 = {:.1} µs, max = {:.1} µs, mean = {:.1} µs",
        t.len(),
        percentile(&t, 0.50).as_secs_f64() * 1e6,
        percentile(&t, 0.99).as_secs_f64() * 1e6,
        t[t.len() - 1].as_secs_f64() * 1e6,
        mean.as_secs_f64() * 1e6,
    );
}

fn store_benches(c: &mut Criterion) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let store = rt
        .block_on(Store::open(dir.path().join("bench.db")))
        .unwrap();
    let reference = rt.block_on(reference(&store));
    let frames: Vec<Vec<u8>> = GEOMETRIES.iter().map(frame).collect();

    // Percentiles from a plain timed loop.
    rt.block_on(async {
        const SCANS: u64 = 200;
        let scans = measuring_scans(&store, reference, SCANS).await;
        let mut one = Vec::new();
        for (k, scan) in scans.iter().enumerate() {
            for g in &GEOMETRIES {
                let v = values(g, k as u64);
                let t0 = Instant::now();
                store
                    .add_reading(*scan, g.device, g, &v, &frames[g.index])
                    .await
                    .unwrap();
                one.push(t0.elapsed());
            }
        }
        report("add_reading (1 reading, 1 commit)", one);

        let scans = measuring_scans(&store, reference, SCANS).await;
        let mut whole = Vec::new();
        for (k, scan) in scans.iter().enumerate() {
            let batch = readings(&frames, k as u64);
            let t0 = Instant::now();
            store.add_readings_tx(*scan, &batch).await.unwrap();
            whole.push(t0.elapsed());
        }
        report("add_readings_tx (14 readings, 1 transaction)", whole);
    });

    let mut group = c.benchmark_group("store");
    group.sample_size(30);
    group.bench_function("add_reading", |b| {
        b.iter_custom(|iters| {
            rt.block_on(async {
                let scans =
                    measuring_scans(&store, reference, iters.div_ceil(GEOMETRY_COUNT as u64)).await;
                let t0 = Instant::now();
                for i in 0..iters {
                    let scan = scans[(i / GEOMETRY_COUNT as u64) as usize];
                    let g = &GEOMETRIES[(i % GEOMETRY_COUNT as u64) as usize];
                    black_box(
                        store
                            .add_reading(scan, g.device, g, &values(g, i), &frames[g.index])
                            .await
                            .unwrap(),
                    );
                }
                t0.elapsed()
            })
        })
    });
    group.bench_function("add_readings_tx_14", |b| {
        b.iter_custom(|iters| {
            rt.block_on(async {
                let scans = measuring_scans(&store, reference, iters).await;
                let t0 = Instant::now();
                for (k, scan) in scans.iter().enumerate() {
                    let batch = readings(&frames, k as u64);
                    black_box(store.add_readings_tx(*scan, &batch).await.unwrap());
                }
                t0.elapsed()
            })
        })
    });
    group.finish();
    rt.block_on(store.close());
}

criterion_group!(benches, store_benches);
criterion_main!(benches);
