//! When an iterative solver stops: the rules a user sets ([`Stopping`]) and their state during a
//! run ([`StopRules`]), the one place where they are applied, by the native loop and by the
//! argmin adapter alike.

use std::collections::VecDeque;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

use super::Termination;

/// When an iterative solver stops. Criteria set to `None` are off.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stopping {
    /// Maximum number of iterations (at least 1).
    pub max_iter: usize,
    /// Stop when the solver's residual measure, relative to its initial value, is at most this.
    pub rel_residual: Option<f64>,
    /// Stop when ‖x_k − x_{k−1}‖ / ‖x_k‖ is at most this.
    pub rel_change: Option<f64>,
    /// Stop when the objective improved by less than `rel` (relative) over the last `window`
    /// iterations.
    pub stagnation: Option<Stagnation>,
    /// Stop after this much wall-clock time (checked after each iteration).
    pub time_limit: Option<Duration>,
}

/// Objective stagnation: an improvement over `window` iterations of at most `rel` times the
/// objective, or at most `floor` (in the objective's units), whichever is larger.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stagnation {
    /// Relative improvement threshold.
    pub rel: f64,
    /// Number of iterations it is measured over.
    pub window: usize,
    /// Absolute improvement threshold (0 for none): e.g. the objective's change below which an
    /// iteration only stirs round-off.
    #[serde(default)]
    pub floor: f64,
}

impl Default for Stopping {
    fn default() -> Self {
        Stopping {
            max_iter: 100,
            rel_residual: Some(1e-6),
            rel_change: None,
            stagnation: None,
            time_limit: None,
        }
    }
}

impl Stopping {
    /// Only an iteration limit.
    pub fn iterations(max_iter: usize) -> Self {
        Stopping {
            max_iter,
            rel_residual: None,
            ..Stopping::default()
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if self.max_iter == 0 {
            return Err(Error::param("max_iter", "must be at least 1"));
        }
        let positive = |name: &'static str, v: Option<f64>| match v {
            Some(t) if !(t.is_finite() && t >= 0.0) => Err(Error::param(
                name,
                format!(
                    "must be a finite number ≥ 0, got {}",
                    crate::units::number(t)
                ),
            )),
            _ => Ok(()),
        };
        positive("rel_residual", self.rel_residual)?;
        positive("rel_change", self.rel_change)?;
        if let Some(s) = self.stagnation {
            positive("stagnation.rel", Some(s.rel))?;
            positive("stagnation.floor", Some(s.floor))?;
            if s.window == 0 {
                return Err(Error::param("stagnation.window", "must be at least 1"));
            }
        }
        Ok(())
    }
}

/// The [`Stopping`] rules during a run: the rules and the recent objectives the stagnation rule
/// compares. Serializable, so that a checkpointed argmin run resumes with them.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct StopRules {
    stopping: Stopping,
    /// The last `window + 1` objectives, for the stagnation rule.
    recent: VecDeque<f64>,
}

impl StopRules {
    pub(crate) fn new(stopping: Stopping) -> Self {
        StopRules {
            stopping,
            recent: VecDeque::new(),
        }
    }

    /// Records an iteration and applies the convergence rules, in order: residual, change,
    /// stagnation.
    pub(crate) fn converged(
        &mut self,
        residual: f64,
        objective: f64,
        change: f64,
    ) -> Option<Termination> {
        let mut stagnated = false;
        if let Some(s) = self.stopping.stagnation {
            self.recent.push_back(objective);
            if self.recent.len() > s.window + 1 {
                self.recent.pop_front();
            }
            if let (true, Some(&old), Some(&new)) = (
                self.recent.len() == s.window + 1,
                self.recent.front(),
                self.recent.back(),
            ) {
                stagnated = (old - new) <= (s.rel * old.abs().max(f64::MIN_POSITIVE)).max(s.floor);
            }
        }
        if self.stopping.rel_residual.is_some_and(|t| residual <= t) {
            Some(Termination::Residual)
        } else if self.stopping.rel_change.is_some_and(|t| change <= t) {
            Some(Termination::Change)
        } else if stagnated {
            Some(Termination::Stagnation)
        } else {
            None
        }
    }

    /// The limits after iteration `it`, `elapsed` into the run: time, then iterations.
    pub(crate) fn limit(&self, it: usize, elapsed: Duration) -> Option<Termination> {
        if self.stopping.time_limit.is_some_and(|t| elapsed >= t) {
            Some(Termination::TimeLimit)
        } else if it >= self.stopping.max_iter {
            Some(Termination::MaxIterations)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `objectives` to rules with only the stagnation rule; the iteration (from 1) at which
    /// it ends the run.
    fn stagnates_at(s: Stagnation, objectives: &[f64]) -> Option<usize> {
        let mut rules = StopRules::new(Stopping {
            rel_residual: None,
            stagnation: Some(s),
            ..Stopping::default()
        });
        objectives
            .iter()
            .position(|&o| rules.converged(1.0, o, 1.0) == Some(Termination::Stagnation))
            .map(|i| i + 1)
    }

    #[test]
    fn stagnation_takes_the_larger_of_its_relative_and_absolute_thresholds() {
        // Falls of 1 an iteration from 100: more than 0.1% of the objective each time; an
        // absolute floor of 2 ends the run at the first comparison, one of 0.5 never.
        let falling: Vec<f64> = (0..10).map(|i| 100.0 - f64::from(i)).collect();
        let rel = |rel, floor| Stagnation {
            rel,
            window: 1,
            floor,
        };
        assert_eq!(stagnates_at(rel(0.001, 0.0), &falling), None);
        assert_eq!(stagnates_at(rel(0.0, 2.0), &falling), Some(2));
        assert_eq!(stagnates_at(rel(0.0, 0.5), &falling), None);
        // A rise ends the run whatever the thresholds.
        assert_eq!(stagnates_at(rel(0.0, 0.0), &[5.0, 4.0, 4.5]), Some(3));
        let bad = Stopping {
            stagnation: Some(rel(0.0, -1.0)),
            ..Stopping::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("stagnation.floor"), "{e}");
    }
}
