//! A sweep's problems dealt out: to the jobs of an array (a [`Shard`] each, merged afterwards
//! by [`merge_compare`](super::merge_compare)) and to the processes of an MPI job (through a
//! [`Space`]), each running whole problems (a simulation and every solver on it) with no
//! communication until the rows are gathered.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::space::{first_failure, Space, WHOLE};

use super::{estimated_work, Case, ExperimentConfig, Row};

/// One share of a sweep's problems: share `index` (from 0) of `count`; written and parsed as
/// `k/n` with k from 1, as job arrays number their tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which share, from 0.
    pub index: usize,
    /// How many shares.
    pub count: usize,
}

impl Shard {
    /// The whole sweep: share 1 of 1.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Parses `k/n` (1 ≤ k ≤ n).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`shard`) for anything else.
    pub fn parse(text: &str) -> Result<Shard> {
        let bad = || {
            Error::param(
                "shard",
                format!("`{text}` is not k/n with 1 ≤ k ≤ n (for example 2/8)"),
            )
        };
        let (k, n) = text.trim().split_once('/').ok_or_else(bad)?;
        let k: usize = k.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        if k == 0 || k > n {
            return Err(bad());
        }
        Ok(Shard {
            index: k - 1,
            count: n,
        })
    }

    /// Whether this is the whole sweep.
    pub fn is_whole(self) -> bool {
        self.count == 1
    }

    /// Checks that `config`'s sweep has a problem for each of the shards: shards deal whole
    /// problems, so more shards than problems would leave some with nothing to run (and a merge
    /// waiting for their folders).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`shard`) when there are more shards than problems.
    pub fn check(self, config: &ExperimentConfig) -> Result<()> {
        let problems = config.problems();
        if self.count > problems {
            let shard = self.to_string();
            return Err(Error::param(
                "shard",
                format!(
                    "{shard}: the sweep has {problems} problems (a simulation and every solver \
                     on it, dealt whole), so at most {problems} shards"
                ),
            ));
        }
        Ok(())
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index + 1, self.count)
    }
}

/// Which problems of a sweep one process runs: its [`Shard`] of the sweep, dealt again over the
/// parts of `space` (the processes of an MPI job; [`WHOLE`] for one process).
#[derive(Debug, Clone, Copy)]
pub struct SweepShare<'a> {
    /// The share of the sweep this job runs.
    pub shard: Shard,
    /// The processes that share it.
    pub space: &'a dyn Space,
}

impl SweepShare<'_> {
    /// The whole sweep on one process.
    pub const WHOLE: SweepShare<'static> = SweepShare {
        shard: Shard::WHOLE,
        space: &WHOLE,
    };

    /// Whether this process runs every problem of the sweep.
    pub fn is_whole(&self) -> bool {
        self.shard.is_whole() && self.space.parts() == 1
    }

    /// Whether this process writes the output folder: the first process of the job.
    pub fn writes(&self) -> bool {
        self.space.part() == 0
    }

    /// The problems of `config` this process runs, in sweep order (none for a shard beyond
    /// the number of problems; see [`Shard::check`]).
    pub fn cases(&self, config: &ExperimentConfig) -> Vec<Case> {
        let all = config.cases();
        if self.shard.index >= all.len() {
            return Vec::new();
        }
        // Every problem has positive work, so shares beyond the number of problems stay empty
        // and the first ones are dealt as if there were no more: no share is made for those.
        let shares = self.shard.count.min(all.len());
        let job = pick(&all, &deal(config, &all, shares)[self.shard.index]);
        let mine = &deal(config, &job, self.space.parts())[self.space.part()];
        pick(&job, mine)
    }

    /// `local`, once every process has reached this point: the first failing process's error
    /// (as [`Error::InvalidParameter`] naming `parts`, unless it is this process's own), or
    /// `local`'s value. A collective: every process calls it at the same point.
    pub(super) fn agree<T>(&self, local: Result<T>) -> Result<T> {
        if self.space.parts() == 1 {
            return local;
        }
        let message = local.as_ref().err().map(ToString::to_string);
        match first_failure(self.space, message.as_deref()) {
            Some((part, m)) if part != self.space.part() => {
                Err(Error::param("parts", format!("process {part}: {m}")))
            }
            _ => local,
        }
    }

    /// Every process's rows, on every process, in sweep order; and whether any process was
    /// interrupted. A collective.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`rows`) if a row cannot be passed as JSON.
    pub(super) fn gather(
        &self,
        config: &ExperimentConfig,
        rows: Vec<Row>,
        interrupted: bool,
    ) -> Result<(Vec<Row>, bool)> {
        if self.space.parts() == 1 {
            return Ok((rows, interrupted));
        }
        let text = serde_json::to_string(&rows)
            .map_err(|e| Error::param("rows", format!("cannot pass the rows on: {e}")));
        let text = self.agree(text)?;
        let mut all = Vec::new();
        for part in crate::space::gather_text(self.space, &text) {
            let rows: Vec<Row> = serde_json::from_str(&part)
                .map_err(|e| Error::param("rows", format!("cannot read a process's rows: {e}")))?;
            all.extend(rows);
        }
        in_sweep_order(config, &mut all);
        let interrupted = !crate::space::all(self.space, !interrupted);
        Ok((all, interrupted))
    }
}

/// The cases at `indices`.
fn pick(cases: &[Case], indices: &[usize]) -> Vec<Case> {
    indices.iter().map(|&i| cases[i]).collect()
}

/// The estimated work of one problem: every solver of `config` on it.
fn case_work(config: &ExperimentConfig, case: &Case) -> f64 {
    config
        .solvers
        .iter()
        .map(|&m| estimated_work(m, config.max_iter.get(m), case.pulse_len))
        .sum()
}

/// `cases` dealt to `count` shares, balanced by estimated work: the largest problem first, each
/// to the share with the least work so far (the lowest-numbered on a tie). Each share lists
/// indices into `cases` in increasing order; a share may be empty when there are fewer problems
/// than shares. Deterministic, so that every process deals alike.
pub fn deal(config: &ExperimentConfig, cases: &[Case], count: usize) -> Vec<Vec<usize>> {
    let count = count.max(1);
    let mut order: Vec<(usize, f64)> = cases
        .iter()
        .enumerate()
        .map(|(i, c)| (i, case_work(config, c)))
        .collect();
    order.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let mut load = vec![0.0_f64; count];
    let mut shares = vec![Vec::new(); count];
    for (i, work) in order {
        let lightest = (0..count)
            .min_by(|&a, &b| load[a].total_cmp(&load[b]).then(a.cmp(&b)))
            .unwrap_or(0);
        load[lightest] += work;
        shares[lightest].push(i);
    }
    for share in &mut shares {
        share.sort_unstable();
    }
    shares
}

/// Where `row` stands in a one-process run of `config`: its problem's position in
/// [`ExperimentConfig::cases`], then its solver's in `config.solvers` (rows that match no
/// problem go last).
fn sweep_position(config: &ExperimentConfig, cases: &[Case], row: &Row) -> (usize, usize) {
    let case = cases.iter().position(|c| {
        c.scene.name() == row.scene
            && c.pulse_len == row.pulse_len
            && c.seed == row.seed
            && c.snr_db == row.snr_db
    });
    let solver = config.solvers.iter().position(|m| m.name() == row.solver);
    (case.unwrap_or(usize::MAX), solver.unwrap_or(usize::MAX))
}

/// Sorts `rows` into the order a one-process run of `config` gives them.
pub fn in_sweep_order(config: &ExperimentConfig, rows: &mut [Row]) {
    let cases = config.cases();
    rows.sort_by_cached_key(|r| sweep_position(config, &cases, r));
}

/// Whether `rows` hold a run twice (two rows of one problem and solver).
pub(super) fn repeated_run(config: &ExperimentConfig, rows: &[Row]) -> Option<usize> {
    let cases = config.cases();
    let mut seen = std::collections::HashSet::new();
    rows.iter()
        .position(|r| !seen.insert(sweep_position(config, &cases, r)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_from_one_and_print_back() {
        let s = Shard::parse("2/8").unwrap();
        assert_eq!(s, Shard { index: 1, count: 8 });
        assert_eq!(s.to_string(), "2/8");
        for bad in ["0/3", "4/3", "3", "a/b", "1/0", "-1/2", ""] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn every_case_is_dealt_once_and_the_work_is_balanced() {
        let config = ExperimentConfig::compare_quick();
        let cases = config.cases();
        for count in [1, 2, 3, 5, 7, cases.len() + 3] {
            let shares = deal(&config, &cases, count);
            assert_eq!(shares.len(), count);
            let mut all: Vec<usize> = shares.iter().flatten().copied().collect();
            all.sort_unstable();
            assert_eq!(all, (0..cases.len()).collect::<Vec<_>>());
            let loads: Vec<f64> = shares
                .iter()
                .map(|s| s.iter().map(|&i| case_work(&config, &cases[i])).sum())
                .collect();
            let largest = cases
                .iter()
                .map(|c| case_work(&config, c))
                .fold(0.0, f64::max);
            let spread = loads.iter().copied().fold(0.0, f64::max)
                - loads.iter().copied().fold(f64::INFINITY, f64::min);
            // Largest-first to the lightest share: no two shares differ by more than one problem.
            assert!(spread <= largest * (1.0 + 1e-12), "{count}: {loads:?}");
        }
    }

    #[test]
    fn more_shards_than_problems_are_refused_and_make_no_share_each() {
        let config = ExperimentConfig::compare_tiny();
        let problems = config.problems();
        let all = config.cases();
        let count = problems + 5;
        let shares = deal(&config, &all, count);
        for index in [0, problems - 1, problems, count - 1] {
            let share = SweepShare {
                shard: Shard { index, count },
                space: &WHOLE,
            };
            assert_eq!(share.cases(&config), pick(&all, &shares[index]), "{index}");
        }
        let huge = SweepShare {
            shard: Shard {
                index: 0,
                count: usize::MAX,
            },
            space: &WHOLE,
        };
        assert_eq!(huge.cases(&config).len(), 1);
        let fits = Shard {
            index: 0,
            count: problems,
        };
        fits.check(&config).unwrap();
        let e = Shard {
            index: 0,
            count: usize::MAX,
        }
        .check(&config)
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("shard:") && e.contains(&format!("at most {problems} shards")),
            "{e}"
        );
    }

    #[test]
    fn shares_of_shards_partition_the_sweep() {
        let config = ExperimentConfig::compare_tiny();
        let mut seen = Vec::new();
        for index in 0..3 {
            let shard = Shard { index, count: 3 };
            seen.extend(
                SweepShare {
                    shard,
                    space: &WHOLE,
                }
                .cases(&config),
            );
        }
        assert_eq!(seen.len(), config.problems());
        for case in config.cases() {
            assert_eq!(seen.iter().filter(|c| **c == case).count(), 1);
        }
    }
}
