//! Reports (feature `report`): the experiments with their tables and figures, the figures
//! themselves (plotters), the cost model of a configuration that `rdlidar info` prints, the
//! operator timer behind `rdlidar bench`, the numerical stress suite behind `rdlidar stress`, and
//! numbers with units.

pub mod cost;
pub mod experiment;
pub mod plot;
pub mod stress;
pub mod timing;
pub mod units;
