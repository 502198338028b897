//! The two ways to split an acquisition of G ADCs over R processes, timed under MPI (feature
//! `mpi`): by pixel rows (what `rdlidar` does: each process holds its rows of every code set;
//! the forward product is summed over the processes, G·K values) and by ADC (each process holds
//! whole code sets, G/R of them, and every unknown; the adjoint is summed over the processes,
//! M·N·K_s values). One iteration of a least-squares solver applies the operator forward and
//! backward once, so the table gives, per split, the time of a forward and an adjoint product
//! with its all-reduce (the slowest process's, median of the repeats), the all-reduce alone,
//! and the values it sums.
//!
//! `cargo bench --features mpi --bench mpi_split` starts itself again under
//! `mpirun -q -n 2` (one rayon thread per process). Environment: `RDLIDAR_SPLIT_SIZE`
//! (default `100x100x40`), `RDLIDAR_SPLIT_PULSE_LENS` (default `2000,10000,100000`),
//! `RDLIDAR_SPLIT_ADCS` (default `2,4`), `RDLIDAR_SPLIT_RANKS` (default 2).

use std::process::Command;
use std::sync::Arc;
use std::time::Instant;

use rdlidar::acquisition::{Acquisition, CodeStore, Streaming};
use rdlidar::distributed::{Mpi, MpiSpace};
use rdlidar::lidar::{Codes, Geometry, Pulse};
use rdlidar::operator::{BoxedOperator, LinearOperator, Part};
use rdlidar::space::{band, Space};

/// Timed repeats after one warm-up.
const REPEATS: usize = 7;

fn env_or(name: &str, default: &str) -> String {
    std::env::var(name).unwrap_or_else(|_| default.to_string())
}

fn list(name: &str, default: &str) -> Vec<usize> {
    env_or(name, default)
        .split(',')
        .map(|v| v.trim().parse().expect("a list of counts"))
        .collect()
}

/// Starts this benchmark under `mpirun` unless it is already one of its processes.
fn launch() -> bool {
    if std::env::var_os("OMPI_COMM_WORLD_SIZE").is_some() || std::env::var_os("PMI_SIZE").is_some()
    {
        return false;
    }
    let ranks = env_or("RDLIDAR_SPLIT_RANKS", "2");
    let status = Command::new("mpirun")
        .args(["-q", "-n", &ranks])
        .arg(std::env::current_exe().expect("the benchmark's path"))
        .env("RAYON_NUM_THREADS", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
        .status()
        .expect("mpirun (Debian: openmpi-bin) runs");
    assert!(status.success(), "mpirun: {status}");
    true
}

/// The operator of `sets` over `g`'s pixels.
fn operator(g: Geometry, pulse: &[f64], sets: Vec<Arc<Codes>>) -> BoxedOperator<f64> {
    Acquisition::new(
        g,
        pulse.to_vec(),
        CodeStore::Held(sets),
        None,
        Streaming::Never,
    )
    .and_then(|a| a.operator::<f64>())
    .expect("the operator")
}

/// The median over the repeats of the slowest process's time of `run`.
fn timed(space: &dyn Space, mut run: impl FnMut()) -> f64 {
    run();
    let mut times: Vec<f64> = (0..REPEATS)
        .map(|_| {
            rdlidar::space::sum(space, 0.0); // start together
            let start = Instant::now();
            run();
            rdlidar::space::max(space, start.elapsed().as_secs_f64())
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[REPEATS / 2]
}

/// The scene's values, deterministic.
fn values(len: usize, offset: usize) -> Vec<f64> {
    (0..len)
        .map(|i| (((i + offset) * 7919) % 1013) as f64 / 1013.0 - 0.5)
        .collect()
}

fn main() {
    if launch() {
        return;
    }
    let mpi = Mpi::init().expect("MPI");
    let world = MpiSpace::world(&mpi);
    let space: Arc<dyn Space> = Arc::new(world);
    let (parts, part) = (space.parts(), space.part());
    let g = Geometry::parse(&env_or("RDLIDAR_SPLIT_SIZE", "100x100x40"))
        .expect("RDLIDAR_SPLIT_SIZE as MxNxKS");
    if part == 0 {
        println!(
            "G ADCs split over {parts} processes, {g}, f64, one rayon thread each; per \
             iteration (forward + adjoint + all-reduce), the slowest process, median of \
             {REPEATS}"
        );
        println!(
            "| K_p | G | split | forward + adjoint (ms) | all-reduce alone (ms) | values summed |"
        );
        println!("|---:|---:|---|---:|---:|---:|");
    }
    for kp in list("RDLIDAR_SPLIT_PULSE_LENS", "2000,10000,100000") {
        for adcs in list("RDLIDAR_SPLIT_ADCS", "2,4") {
            if adcs < parts {
                continue;
            }
            let k = g.samples(kp);
            let pulse = Pulse::<f64>::bernoulli(kp, 1).expect("pulse").into_inner();
            let sets: Vec<Arc<Codes>> = (0..adcs)
                .map(|s| Arc::new(Codes::random_binary(g.pixels(), k, 10 + s as u64).unwrap()))
                .collect();
            // By rows: this process's rows of every code set, the forward product summed.
            let rows = band(g.m, parts, part);
            let pixels: Vec<usize> = (rows.start * g.n..rows.end * g.n).collect();
            let band_geometry = Geometry::new(rows.len(), g.n, g.ks).expect("band");
            let mine: Vec<Arc<Codes>> = sets
                .iter()
                .map(|c| Arc::new(c.select_pixels(&pixels).expect("band codes")))
                .collect();
            let by_rows = Part::new(operator(band_geometry, &pulse, mine), Arc::clone(&space));
            let x_band = values(by_rows.ncols(), rows.start * g.n * g.ks);
            let mut y = vec![0.0; by_rows.nrows()];
            let mut x_back = vec![0.0; by_rows.ncols()];
            let rows_time = timed(&*space, || {
                by_rows.apply(&x_band, &mut y);
                by_rows.apply_adjoint(&y, &mut x_back);
            });
            let mut reduced = vec![0.0; adcs * k];
            let rows_reduce = timed(&*space, || space.sum(&mut reduced));
            // By ADC: whole code sets (every parts-th), every unknown, the adjoint summed.
            let my_sets: Vec<Arc<Codes>> = sets
                .iter()
                .enumerate()
                .filter(|(s, _)| s % parts == part)
                .map(|(_, c)| Arc::clone(c))
                .collect();
            let by_adc = operator(g, &pulse, my_sets);
            let x = values(g.pixels() * g.ks, 0);
            let mut y_mine = vec![0.0; by_adc.nrows()];
            let mut x_sum = vec![0.0; x.len()];
            let adc_time = timed(&*space, || {
                by_adc.apply(&x, &mut y_mine);
                by_adc.apply_adjoint(&y_mine, &mut x_sum);
                space.sum(&mut x_sum);
            });
            let adc_reduce = timed(&*space, || space.sum(&mut x_sum));
            // The two splits compute the same products.
            by_adc.apply(&x, &mut y_mine);
            by_adc.apply_adjoint(&y_mine, &mut x_sum);
            space.sum(&mut x_sum);
            let whole_back = space.gather(&x_back);
            let gap = whole_back
                .iter()
                .zip(&x_sum)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
                / x_sum.iter().fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
            assert!(gap < 1e-9, "the splits' backprojections differ by {gap:e}");
            if part == 0 {
                for (split, time, reduce, values) in [
                    ("rows", rows_time, rows_reduce, adcs * k),
                    ("ADCs", adc_time, adc_reduce, g.pixels() * g.ks),
                ] {
                    println!(
                        "| {kp} | {adcs} | {split} | {:.1} | {:.2} | {values} |",
                        time * 1e3,
                        reduce * 1e3
                    );
                }
            }
        }
    }
}
