//! Unknowns split across MPI processes (feature `mpi`): the [`Space`] of an MPI communicator.
//!
//! Every rank holds its part of the unknowns, as an [`operator::Part`](crate::operator::Part)
//! whose block is the operator of its own unknowns (for the lidar, of a band of image rows,
//! [`RdOperator::row_band`](crate::lidar::RdOperator::row_band)), and the measurements whole.
//! The solvers and reconstructions then run on every rank at once, unchanged: they compute their
//! inner products, norms and selections through an [`MpiSpace`], whose collectives are MPI's.
//!
//! ```no_run
//! use std::sync::Arc;
//! use rdlidar::distributed::{Mpi, MpiSpace};
//! use rdlidar::lidar::RdOperator;
//! use rdlidar::operator::Part;
//!
//! /// This rank's rows of the least-squares solution of `whole` x = `y`.
//! fn my_rows(mpi: &Mpi, whole: &RdOperator<f64>, y: &[f64]) -> rdlidar::Result<Vec<f64>> {
//!     let space = MpiSpace::world(mpi);
//!     let rows = space.band(whole.geometry().m); // this rank's rows of the image
//!     let part = Part::new(whole.row_band(rows)?, Arc::new(space));
//!     let mut x = vec![0.0; rdlidar::LinearOperator::ncols(&part)];
//!     rdlidar::solver::cgls(&part, y, &mut x, &Default::default(), &mut ())?;
//!     Ok(x)
//! }
//! // Mpi::init() once per process, before any other MPI call; hold it while solving.
//! ```

use std::ops::Range;

use mpi::collective::SystemOperation;
use mpi::datatype::PartitionMut;
use mpi::environment::Universe;
use mpi::topology::SimpleCommunicator;
use mpi::traits::{Communicator, CommunicatorCollectives};
use mpi::Threading;

use crate::error::{Error, Result};
use crate::space::{self, Space};

/// MPI, initialized for this process; finalized when dropped. Hold it for as long as any
/// [`MpiSpace`] is used.
pub struct Mpi {
    universe: Universe,
}

impl Mpi {
    /// Initializes MPI with serialized threading (the solvers call collectives from one thread
    /// at a time, rayon's workers none). Run under `mpirun -n R`, or alone as one rank.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when MPI is already initialized or does not provide
    /// serialized threading.
    pub fn init() -> Result<Self> {
        let (universe, threading) = mpi::initialize_with_threading(Threading::Serialized)
            .ok_or_else(|| Error::param("mpi", "MPI is already initialized in this process"))?;
        if threading < Threading::Serialized {
            return Err(Error::param(
                "mpi",
                format!("the MPI library provides {threading:?} threading, serialized is needed"),
            ));
        }
        Ok(Self { universe })
    }

    /// This process's rank in the world.
    pub fn rank(&self) -> usize {
        self.universe.world().rank() as usize
    }

    /// The number of processes in the world.
    pub fn size(&self) -> usize {
        self.universe.world().size() as usize
    }
}

/// The space of unknowns split over the ranks of an MPI communicator, in rank order.
///
/// Sums and maxima are MPI all-reductions: every rank receives the same value (MPI's order of
/// addition, which may differ from a one-process run's by round-off); gathers concatenate the
/// ranks' values in rank order.
pub struct MpiSpace {
    comm: SimpleCommunicator,
}

// SAFETY: MPI is initialized with serialized threading (`Mpi::init`): any thread may call it as
// long as no two calls overlap. A space's collectives are called by the solver that holds its
// operator, from one thread at a time; the kernels' worker threads never call them.
unsafe impl Send for MpiSpace {}
// SAFETY: as for `Send`: shared references only make collective calls, serialized as above.
unsafe impl Sync for MpiSpace {}

impl std::fmt::Debug for MpiSpace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MpiSpace(rank {} of {})", self.rank(), self.parts())
    }
}

impl MpiSpace {
    /// The world: every process of the job.
    pub fn world(mpi: &Mpi) -> Self {
        Self {
            comm: mpi.universe.world(),
        }
    }

    /// This process's rank.
    pub fn rank(&self) -> usize {
        self.comm.rank() as usize
    }

    /// This rank's share of `rows` rows split as evenly as the ranks allow, in rank order (the
    /// first ranks take one row more when they do not divide evenly; see [`space::band`]).
    /// Empty for ranks beyond the rows.
    pub fn band(&self, rows: usize) -> Range<usize> {
        space::my_band(self, rows)
    }

    /// Every rank's count of items (`local` here), in rank order.
    fn counts(&self, local: usize) -> Vec<usize> {
        let mut all = vec![0u64; self.parts()];
        self.comm.all_gather_into(&(local as u64), &mut all[..]);
        all.into_iter().map(|c| c as usize).collect()
    }
}

impl Space for MpiSpace {
    fn parts(&self) -> usize {
        self.comm.size() as usize
    }

    fn part(&self) -> usize {
        self.rank()
    }

    fn sum(&self, values: &mut [f64]) {
        let local = values.to_vec();
        self.comm
            .all_reduce_into(&local[..], values, SystemOperation::sum());
    }

    fn max(&self, values: &mut [f64]) {
        let local = values.to_vec();
        self.comm
            .all_reduce_into(&local[..], values, SystemOperation::max());
    }

    fn gather(&self, local: &[f64]) -> Vec<f64> {
        self.gather_of(local, 0.0)
    }

    fn gather_bytes(&self, local: &[u8]) -> Vec<u8> {
        self.gather_of(local, 0u8)
    }

    fn offset(&self, local_len: usize) -> usize {
        self.counts(local_len)[..self.rank()].iter().sum()
    }
}

impl MpiSpace {
    /// Every rank's `local` values, concatenated in rank order.
    ///
    /// # Panics
    /// When the values exceed MPI's counts (2^31 − 1 per rank).
    fn gather_of<V: mpi::datatype::Equivalence + Copy>(&self, local: &[V], zero: V) -> Vec<V> {
        let counts = self.counts(local.len());
        let total: usize = counts.iter().sum();
        let too_many = || -> ! {
            panic!("an MPI gather of {total} values exceeds MPI's counts (2^31 − 1 per rank)")
        };
        let counts: Vec<i32> = counts
            .iter()
            .map(|&c| i32::try_from(c).unwrap_or_else(|_| too_many()))
            .collect();
        let displs: Vec<i32> = counts
            .iter()
            .scan(0i64, |at, &c| {
                let d = *at;
                *at += i64::from(c);
                Some(i32::try_from(d).unwrap_or_else(|_| too_many()))
            })
            .collect();
        let mut all = vec![zero; total];
        let mut partition = PartitionMut::new(&mut all[..], counts, displs);
        self.comm.all_gather_varcount_into(local, &mut partition);
        all
    }
}
