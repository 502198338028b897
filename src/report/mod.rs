//! Reports (feature `report`): the experiments with their tables and figures, the cost model of
//! a configuration that `rdlidar info` prints, the operator timer behind `rdlidar bench`, and
//! numbers with units.

pub mod cost;
pub mod experiment;
pub mod timing;
pub mod units;
