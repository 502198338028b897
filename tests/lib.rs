//! The integration test suite: one binary, one module per area.

mod common;

mod algebra;
mod amp;
mod architectures;
mod argmin_solvers;
mod auto;
mod blocks;
mod censor;
mod cli;
mod cli_adjoint;
mod cli_architecture_variants;
mod cli_architectures;
mod cli_bad_input;
mod cli_bench;
mod cli_codes;
mod cli_dottest;
mod cli_errors;
mod cli_experiments;
mod cli_faults;
mod cli_file_checks;
mod cli_forward;
mod cli_front_door;
mod cli_reconstruct;
mod cli_scene_png;
mod cli_shards;
mod cli_simulate;
mod cli_support;
mod cli_usage;
mod codes;
mod continuous;
mod convolution;
mod degenerate;
mod detection;
mod end_to_end;
mod errors;
mod experiments;
mod hard_scenes;
mod info;
mod io_files;
mod iteration;
#[cfg(feature = "lapack")]
mod lapack;
mod metrics;
mod model_based;
#[cfg(feature = "mpi")]
mod mpi;
#[cfg(feature = "mpi")]
mod mpi_cli;
#[cfg(feature = "mpi")]
mod mpi_sweeps;
mod noise;
mod norm;
mod npy_fuzz;
mod operators;
mod photon;
mod plot;
mod rdop;
mod recon_architectures;
mod reconstruct;
mod scenes;
mod seeded_codes;
mod settings;
mod simulate_noise;
mod solvers;
mod sparse_solvers;
mod split;
mod streamed;
mod stress;
mod tight_frame;
mod tv;
mod weighted;
