//! The solvers and reconstructions on unknowns split over MPI ranks (feature `mpi`): each test
//! starts itself again under `mpirun -n R` (R = 1, 2, 3, oversubscribing the cores), and every
//! rank solves its band of image rows through an [`MpiSpace`], gathers the whole result and
//! compares it with the one-process run it computes alone. A rank that disagrees panics, which
//! fails the job; a job that does not end in time is killed and fails the test.
//!
//! Needs `mpirun` (Debian: openmpi-bin); as root, OpenMPI's run-as-root variables are set here.

use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

use rdlidar::distributed::{Mpi, MpiSpace};
use rdlidar::lidar::{paper_scene, semi_transparent_scene, Codes, Geometry, Pulse, RdOperator};
use rdlidar::operator::{LinearOperator, Part};
use rdlidar::recon::{reconstruct, Method, ReconstructOptions};
use rdlidar::solver::{cgls, CglsParams, Stopping};

/// Set in the ranks' environment: run the test's body instead of launching it.
const RANK_VAR: &str = "RDLIDAR_TEST_MPI_RANK";

/// How long one job may take before it is killed.
const JOB_LIMIT: Duration = Duration::from_secs(300);

/// Runs the test `name` of this binary under `mpirun -n R` for R = 1, 2, 3; returns whether
/// this process is a rank (which then runs the body).
fn launched(name: &str) -> bool {
    if std::env::var_os(RANK_VAR).is_some() {
        return true;
    }
    let exe = std::env::current_exe().unwrap();
    for ranks in [1, 2, 3] {
        let mut child = Command::new("mpirun")
            .args(["-n", &ranks.to_string()])
            .arg(&exe)
            .args([name, "--exact", "--test-threads=1", "--nocapture"])
            .env(RANK_VAR, "1")
            .env("RAYON_NUM_THREADS", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
            .spawn()
            .expect("mpirun (Debian: openmpi-bin) runs");
        let start = Instant::now();
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if start.elapsed() > JOB_LIMIT {
                let _ = child.kill();
                panic!("{name} under mpirun -n {ranks} did not end in {JOB_LIMIT:?}");
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        assert!(status.success(), "{name} under mpirun -n {ranks}: {status}");
    }
    false
}

fn measured(
    truth: &rdlidar::lidar::Scene<f64>,
    kp: usize,
    seed: u64,
) -> (RdOperator<f64>, Vec<f64>) {
    let g = truth.geometry();
    let pulse = Pulse::<f64>::bernoulli(kp, seed).unwrap().into_inner();
    let codes = Codes::random_binary(g.pixels(), g.samples(kp), seed + 1).unwrap();
    let op = RdOperator::new(g, pulse, Arc::new(codes)).unwrap();
    let mut y = vec![0.0; op.nrows()];
    op.apply(truth.as_slice(), &mut y);
    (op, y)
}

/// This rank's part of `whole`: the operator of its band of rows.
fn my_part(whole: &RdOperator<f64>, space: MpiSpace) -> Part<RdOperator<f64>> {
    let rows = space.band(whole.geometry().m);
    Part::new(whole.row_band(rows).unwrap(), Arc::new(space))
}

fn support(x: &[f64]) -> Vec<usize> {
    (0..x.len()).filter(|&i| x[i] != 0.0).collect()
}

/// The gathered split result is the whole one: the same support, values within `tol` of the
/// largest.
fn assert_close(what: &str, rank: usize, whole: &[f64], split: &[f64], tol: f64) {
    assert_eq!(
        support(whole),
        support(split),
        "rank {rank}, {what}: supports differ"
    );
    let scale = whole.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = whole
        .iter()
        .zip(split)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        worst <= tol * scale,
        "rank {rank}, {what}: values differ by {worst:e} of {scale:e}"
    );
}

#[test]
fn cgls_and_every_way_of_auto_on_mpi_ranks_are_the_one_process_runs() {
    if !launched("mpi::cgls_and_every_way_of_auto_on_mpi_ranks_are_the_one_process_runs") {
        return;
    }
    let mpi = Mpi::init().unwrap();
    let rank = mpi.rank();
    let g = Geometry::new(12, 12, 16).unwrap();

    // CGLS, 30 iterations on a redundant problem.
    let (op, y) = measured(&paper_scene(g).unwrap(), 3000, 11);
    let params = CglsParams {
        stopping: Stopping {
            max_iter: 30,
            ..Stopping::default()
        },
        ..CglsParams::default()
    };
    let mut whole = vec![0.0; op.ncols()];
    let serial = cgls(&op, &y, &mut whole, &params, &mut ()).unwrap();
    let part = my_part(&op, MpiSpace::world(&mpi));
    let mut x = vec![0.0; part.ncols()];
    let report = cgls(&part, &y, &mut x, &params, &mut ()).unwrap();
    assert_eq!(
        report.iterations, serial.iterations,
        "rank {rank}: CGLS iterations"
    );
    let gathered = rdlidar::space::Space::gather(part.space(), &x);
    assert_close("CGLS", rank, &whole, &gathered, 1e-8);

    // Auto: TV on the depth map (compressive), several returns per pixel (at 30 dB below, noise
    // free here with more measurements).
    let options = ReconstructOptions::default();
    let semi = semi_transparent_scene(g, 2..=3, 9).unwrap();
    for (what, truth, kp) in [
        ("auto through TV", paper_scene(g).unwrap(), 200),
        ("auto, several returns", semi, 1200),
    ] {
        let (op, y) = measured(&truth, kp, 5);
        let serial = reconstruct(&op, &y, Method::Auto, &options).unwrap();
        let part = my_part(&op, MpiSpace::world(&mpi));
        let split = reconstruct(&part, &y, Method::Auto, &options).unwrap();
        assert_eq!(split.method_used, serial.method_used, "rank {rank}, {what}");
        // Coarse-to-fine needs the whole scene in one process: the one-process run may try it
        // (here without keeping it), the ranks do not.
        let stages = |r: &rdlidar::recon::Reconstruction<f64>| -> Vec<(Method, usize)> {
            r.stages
                .iter()
                .filter(|s| s.method != Method::CoarseToFine)
                .map(|s| (s.method, s.returns))
                .collect()
        };
        assert_eq!(
            stages(&split),
            stages(&serial),
            "rank {rank}, {what}: stages"
        );
        let gathered = rdlidar::space::Space::gather(part.space(), split.scene.as_slice());
        assert_close(what, rank, serial.scene.as_slice(), &gathered, 1e-8);
    }
}
