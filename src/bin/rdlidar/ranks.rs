//! The processes of an MPI job. Under `mpirun -n R` (a binary built with the feature `mpi`),
//! `forward`, `adjoint`, `dottest` and `reconstruct` split the pixel rows over the R processes
//! (`compare` deals its problems to them instead, see `experiment.rs`):
//! every process reads its rows of the codes and computes on them, process 0 prints and writes
//! the outputs, and the processes agree on every failure before going on, so that a bad input
//! ends every process with one error line (process 0's) and status 1, never a wait.
//! Alone, or under `mpirun -n 1`, a command runs as it always does.

use std::sync::Arc;

use std::path::Path;

use rdlidar::acquisition::{AcquisitionFiles, InputNames};
use rdlidar::io;
use rdlidar::lidar::TileSize;
use rdlidar::space::Space;

use rdlidar::acquisition::{Acquisition, Use};
use rdlidar::Real;

use crate::common::{silence, streaming, CliResult, Failure, MeasurementFiles};

/// The rank and size of the job this process was launched in by `mpirun`/`mpiexec` (OpenMPI's
/// or a PMI launcher's variables), if any.
fn launched() -> Option<(usize, usize)> {
    let var = |name: &str| std::env::var(name).ok()?.trim().parse::<usize>().ok();
    [
        ("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"),
        ("PMI_RANK", "PMI_SIZE"),
        ("PMIX_RANK", "PMIX_SIZE"),
    ]
    .iter()
    .find_map(|(rank, size)| Some((var(rank)?, var(size)?)))
}

/// The processes a command runs on: this one alone, or this one's part of an MPI job.
pub struct Ranks {
    #[cfg(feature = "mpi")]
    _mpi: Option<rdlidar::distributed::Mpi>,
    space: Option<Arc<dyn Space>>,
}

impl Ranks {
    /// One process.
    pub fn alone() -> Ranks {
        Ranks {
            #[cfg(feature = "mpi")]
            _mpi: None,
            space: None,
        }
    }

    /// The processes of `command`: this one alone unless it was launched as one of several
    /// processes; then MPI's (`splits` says whether the command splits its rows over them).
    ///
    /// # Errors
    /// Several processes for a command that does not split its work, or a binary built without
    /// the feature `mpi` (every process would run the whole command and write the same files).
    pub fn start(command: &str, splits: bool) -> CliResult<Ranks> {
        let Some((rank, size)) = launched().filter(|&(_, size)| size > 1) else {
            return Ok(Ranks::alone());
        };
        if rank > 0 {
            silence();
        }
        if !splits {
            return Err(format!(
                "rdlidar {command} runs on one process, but it was launched as {size} \
                 processes: run it without mpirun (under mpirun, forward, adjoint, dottest and \
                 reconstruct split the pixel rows over the processes, simulate too with \
                 --codes-format seed, reconstruct --tiles deals the tiles to them, and compare \
                 without --merge deals its problems to them)"
            )
            .into());
        }
        Ranks::world(command, size)
    }

    #[cfg(feature = "mpi")]
    fn world(_command: &str, size: usize) -> CliResult<Ranks> {
        use rdlidar::distributed::{Mpi, MpiSpace};
        let mpi = Mpi::init()?;
        if mpi.size() != size {
            return Err(format!(
                "the launcher started {size} processes, but MPI sees {}: was this rdlidar built \
                 against the MPI library of this mpirun?",
                mpi.size()
            )
            .into());
        }
        let space: Arc<dyn Space> = Arc::new(MpiSpace::world(&mpi));
        Ok(Ranks {
            _mpi: Some(mpi),
            space: Some(space),
        })
    }

    #[cfg(not(feature = "mpi"))]
    fn world(command: &str, size: usize) -> CliResult<Ranks> {
        Err(format!(
            "rdlidar {command} was launched as {size} processes, but this rdlidar was built \
             without MPI: build it with `cargo build --release --features mpi` (OpenMPI or \
             MPICH, and libclang) to split the work over the processes"
        )
        .into())
    }

    /// Reads `files`' measurements in `T` and this process's acquisition (its rows, when the rows
    /// are split over processes), after checking that `command`, holding `scenes` scenes, fits
    /// in memory as `request` uses the operator. `tiles` and `stream_codes` are the flags.
    pub fn load<T: Real>(
        &self,
        inputs: &MeasurementFiles,
        (tiles, stream_codes): (Option<TileSize>, bool),
        (command, scenes, request): (&str, u128, Use),
    ) -> CliResult<(Acquisition, Vec<T>)> {
        let p = io::read_pulse::<f64>(&inputs.pulse)?;
        let files = self.describe(
            &inputs.codes,
            (p.len(), inputs.depth_bins),
            None,
            tiles,
            stream_codes,
        )?;
        let y = files.read_measurements::<T>(&inputs.meas)?;
        files.check_memory::<T>(command, scenes, request)?;
        let acq = files.load(p.into_inner())?;
        Ok((acq, y))
    }

    /// The codes `codes` described for a pulse of `pulse_len` samples and `depth_bins` bins
    /// (a scene of `grid` pixels, when given), with the command line's `--tiles` and
    /// `--stream-codes`, split by pixel rows over the processes when there are several.
    ///
    /// # Errors
    /// [`AcquisitionFiles::describe`]; [`AcquisitionFiles::split_over`].
    pub fn describe(
        &self,
        codes: &Path,
        (pulse_len, depth_bins): (usize, usize),
        grid: Option<(usize, usize)>,
        tiles: Option<TileSize>,
        stream_codes: bool,
    ) -> CliResult<AcquisitionFiles> {
        let files = AcquisitionFiles::describe(
            codes,
            pulse_len,
            depth_bins,
            grid,
            tiles,
            streaming(stream_codes),
            InputNames::COMMAND_LINE,
        )?;
        self.split(files)
    }

    /// `files` split by pixel rows over the processes, when there are several.
    ///
    /// # Errors
    /// [`AcquisitionFiles::split_over`].
    fn split(&self, files: AcquisitionFiles) -> CliResult<AcquisitionFiles> {
        let Some(space) = &self.space else {
            return Ok(files);
        };
        files.split_over(Arc::clone(space)).map_err(|e| match e {
            rdlidar::Error::InvalidParameter { name, reason }
                if name == "parts" || name == "tiles" =>
            {
                Failure::Message(format!("mpirun -n {}: {reason}", space.parts()))
            }
            other => other.into(),
        })
    }

    /// The space of the processes, when there are several.
    pub fn space(&self) -> Option<&Arc<dyn Space>> {
        self.space.as_ref()
    }

    /// How many processes run the command.
    pub fn processes(&self) -> usize {
        self.space.as_ref().map_or(1, |s| s.parts())
    }

    /// Whether this is the process that prints and writes: the first (or the only) one.
    pub fn is_first(&self) -> bool {
        self.space.as_ref().is_none_or(|s| s.part() == 0)
    }

    /// `local`, this process's outcome of a step, once every process has reached the same
    /// point: an error when any process failed (the first failing process's message, which
    /// process 0 prints), otherwise `local`'s value. A collective: every process calls it at
    /// the same point.
    pub fn agree<T>(&self, local: CliResult<T>) -> CliResult<T> {
        let Some(space) = &self.space else {
            return local;
        };
        let message = match &local {
            Ok(_) => None,
            Err(Failure::Message(m)) => Some(m.clone()),
            Err(Failure::BrokenPipe) => Some("standard output is closed".to_string()),
        };
        match rdlidar::space::first_failure(&**space, message.as_deref()) {
            None => local,
            Some((part, _)) if part == space.part() => local,
            Some((0, m)) => Err(Failure::Message(m)),
            Some((part, m)) => Err(Failure::Message(format!("process {part}: {m}"))),
        }
    }
}
