//! Testbed studies: how a lidar's retrieval behaves over many atmospheres.
//!
//! * [`dial`]: a scene's instrument and retrievals run for every profile of an ensemble, with
//!   the error of each profile's retrieval and an error budget per class and line pair (the
//!   reference study (docs/design.md): 300 NWP-perturbed profiles per latitude class);
//! * [`select`]: sensitivities of candidate on/off line positions (line selection), set up and
//!   summarised as `lidarsim select-lines` does by [`select_study`].
//!
//! [`shard`] and [`select_shard`] run slices of either study and merge them.
//!
//! Both call the stages (atmosphere, spectroscopy, optics, lidar equation, instrument,
//! retrieval) directly, once per profile, without files in between.

pub mod dial;
pub mod select;
pub mod select_shard;
pub mod select_study;
pub mod shard;

/// The profiles of a study that failed for one reason: how many, and the first of them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FailureGroup {
    /// Profiles that failed for this reason.
    pub count: usize,
    /// The first of them, in the study's order.
    pub id: String,
    /// Its reason, as reported.
    pub reason: String,
}

impl std::fmt::Display for FailureGroup {
    /// `2 profiles: <the first reason> (profile <id> and 1 more)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = if self.count == 1 { "" } else { "s" };
        write!(
            f,
            "{} profile{s}: {} (profile {}",
            self.count, self.reason, self.id
        )?;
        if self.count > 1 {
            write!(f, " and {} more", self.count - 1)?;
        }
        write!(f, ")")
    }
}

/// The failures `(profile id, reason)` of a study grouped by reason, in order of first
/// appearance, so that a report says each reason once, not once per profile. Two reasons are
/// the same when they differ only in their numbers and the profile's own id
/// (`supersaturated: relative humidity 355.4 % at 0 m` and `… 416.7 % at 0 m`).
pub fn group_failures<'a>(
    failures: impl IntoIterator<Item = (&'a str, &'a str)>,
) -> Vec<FailureGroup> {
    let mut groups: Vec<(String, FailureGroup)> = Vec::new();
    for (id, reason) in failures {
        let key = reason_kind(reason, id);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, g)) => g.count += 1,
            None => groups.push((
                key,
                FailureGroup {
                    count: 1,
                    id: id.to_string(),
                    reason: reason.to_string(),
                },
            )),
        }
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

/// `reason` with the profile's `id` and every number replaced by placeholders.
fn reason_kind(reason: &str, id: &str) -> String {
    let text = if id.is_empty() {
        reason.to_string()
    } else {
        reason.replace(id, "\u{1}")
    };
    let mut out = String::with_capacity(text.len());
    let mut in_number = false;
    for c in text.chars() {
        if c.is_ascii_digit() || (in_number && c == '.') {
            if !in_number {
                out.push('#');
                in_number = true;
            }
        } else {
            in_number = false;
            out.push(c);
        }
    }
    out
}

/// The one line that says a whole study of the profiles `of` (a set file, an ensemble)
/// failed: `every profile of <of> failed (N of N): <each reason once, with its count and first
/// profile>; nothing was written`.
pub fn all_failed_message(of: &str, groups: &[FailureGroup]) -> String {
    let n: usize = groups.iter().map(|g| g.count).sum();
    let each: Vec<String> = groups.iter().map(|g| g.to_string()).collect();
    format!(
        "every profile of {of} failed ({n} of {n}): {}; nothing was written",
        each.join("; ")
    )
}

/// What a study does with profiles that fail (cannot be run, are supersaturated, a retrieval
/// fails): the decision [`FailureReport::verdict`] makes for `dial`, `select-lines` and the
/// merge of their shards, so that the exit code of a study tells the truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FailurePolicy {
    /// A study where some profiles fail succeeds: they are left out of the statistics, listed
    /// in `failed.csv` and counted by reason in the report. Only a study where every profile
    /// failed is an error (it has nothing to report).
    #[default]
    Tolerate,
    /// Any failed profile makes the study an error, with the same summary, and nothing is
    /// written (`--strict`).
    Strict,
}

impl FailurePolicy {
    /// [`FailurePolicy::Strict`] when `strict` (a command line's `--strict`), else
    /// [`FailurePolicy::Tolerate`].
    pub fn strict_if(strict: bool) -> FailurePolicy {
        if strict {
            FailurePolicy::Strict
        } else {
            FailurePolicy::Tolerate
        }
    }
}

/// The failures of a study of `total` profiles, grouped by reason ([`group_failures`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FailureReport {
    /// Profiles of the study.
    pub total: usize,
    /// Each reason once, in order of first appearance.
    pub groups: Vec<FailureGroup>,
}

impl FailureReport {
    /// The report of a study of `total` profiles whose failed ones are `failures`
    /// `(profile id, reason)`, in the study's order.
    pub fn new<'a>(
        total: usize,
        failures: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> FailureReport {
        FailureReport {
            total,
            groups: group_failures(failures),
        }
    }

    /// Profiles that failed.
    pub fn failed(&self) -> usize {
        self.groups.iter().map(|g| g.count).sum()
    }

    /// Whether every profile of a study that had some failed: it has nothing to report.
    pub fn all_failed(&self) -> bool {
        self.total > 0 && self.failed() == self.total
    }

    /// Whether the study of the profiles `of` (a set file, an ensemble) may write its products
    /// under `policy`: `Err` with the one line that says why not ([`all_failed_message`], or
    /// with [`FailurePolicy::Strict`] `N of M profiles of <of> failed (strict: …): <each
    /// reason once, with its count and first profile>; nothing was written`).
    pub fn verdict(&self, of: &str, policy: FailurePolicy) -> Result<(), String> {
        let failed = self.failed();
        if self.all_failed() {
            return Err(all_failed_message(of, &self.groups));
        }
        if policy == FailurePolicy::Strict && failed > 0 {
            let each: Vec<String> = self.groups.iter().map(|g| g.to_string()).collect();
            return Err(format!(
                "{failed} of {} profiles of {of} failed (strict: any failed profile is an error): {}; nothing was written",
                self.total,
                each.join("; ")
            ));
        }
        Ok(())
    }
}

impl FailureReport {
    /// [`Self::verdict`] before a study runs, on the profiles found unable to run
    /// ([`dial::unusable`]): with [`FailurePolicy::Strict`] any of them refuses the study
    /// (`N of M profiles of <of> cannot be run (strict: …): <each reason once>; nothing was
    /// run`; when none can, the line a study where every profile failed gives); otherwise the
    /// study runs and leaves them out.
    pub fn verdict_before_run(&self, of: &str, policy: FailurePolicy) -> Result<(), String> {
        let failed = self.failed();
        if policy == FailurePolicy::Strict && self.all_failed() {
            return Err(all_failed_message(of, &self.groups));
        }
        if policy == FailurePolicy::Strict && failed > 0 {
            let each: Vec<String> = self.groups.iter().map(|g| g.to_string()).collect();
            return Err(format!(
                "{failed} of {} profiles of {of} cannot be run (strict: any failed profile is an error): {}; nothing was run",
                self.total,
                each.join("; ")
            ));
        }
        Ok(())
    }
}

/// The worker threads a study runs on for `--threads requested` (0: all cores) with `cores`
/// available: at most the cores. A study's work is computation, so a thread beyond the cores
/// only waits for one, and hundreds of them waiting on the nested parallel line-by-line loops
/// cost their own seconds (`dial --threads 1000`: 27 s instead of 0.2 s on 2 cores). The
/// numbers do not depend on the thread count.
pub fn threads(requested: usize, cores: usize) -> usize {
    let cores = cores.max(1);
    if requested == 0 {
        cores
    } else {
        requested.min(cores)
    }
}

/// The thread pool of a study (`dial`, `select-lines`, their shards): [`threads`] of
/// the cores this process may use (`available_parallelism`: its CPU affinity and cgroup
/// quota, e.g. a Slurm job's `--cpus-per-task`), with a warning when `--threads` asked for
/// more.
pub fn thread_pool(requested: usize) -> Result<rayon::ThreadPool, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = threads(requested, cores);
    if threads < requested {
        crate::limits::warn(&format!(
            "--threads {requested}: {cores} cores available, running on {threads} threads (threads beyond the cores only wait; the results are the same)"
        ));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start {threads} threads: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--threads 0` is every core; more than the cores is capped at them; fewer are kept.
    #[test]
    fn a_study_runs_on_at_most_the_cores() {
        assert_eq!(threads(0, 8), 8);
        assert_eq!(threads(3, 8), 3);
        assert_eq!(threads(1000, 2), 2);
        assert_eq!(threads(1024, 64), 64);
        // An unknown core count is one.
        assert_eq!(threads(0, 0), 1);
        assert_eq!(threads(4, 0), 1);
    }

    #[test]
    fn failures_are_grouped_by_reason_with_their_first_profile() {
        let failures = [
            (
                "mid-0001",
                "supersaturated: relative humidity 355.4 % at 0 m (1014.4 hPa)",
            ),
            (
                "mid-0002",
                "the profile ends at 30000 m, below `atmosphere.top_m` 60000 m",
            ),
            (
                "mid-0003",
                "supersaturated: relative humidity 416.7 % at 250 m (990.1 hPa)",
            ),
            ("x1", "profile `x1` has no CO2"),
            ("x2", "profile `x2` has no CO2"),
        ];
        let g = group_failures(failures);
        assert_eq!(g.len(), 3, "{g:?}");
        assert_eq!((g[0].count, g[0].id.as_str()), (2, "mid-0001"));
        assert_eq!((g[1].count, g[1].id.as_str()), (1, "mid-0002"));
        assert_eq!((g[2].count, g[2].id.as_str()), (2, "x1"));
        assert_eq!(
            g[0].to_string(),
            "2 profiles: supersaturated: relative humidity 355.4 % at 0 m (1014.4 hPa) (profile mid-0001 and 1 more)"
        );
        assert_eq!(
            g[1].to_string(),
            "1 profile: the profile ends at 30000 m, below `atmosphere.top_m` 60000 m (profile mid-0002)"
        );
        assert!(
            all_failed_message("set.csv", &g)
                .starts_with("every profile of set.csv failed (5 of 5): 2 profiles: ")
        );
    }

    /// Tolerated: a study with some failed profiles passes, one with all fails; strict: any
    /// failure fails, with the counts by reason; none failed passes either way.
    #[test]
    fn the_verdict_follows_the_policy() {
        use FailurePolicy::{Strict, Tolerate};
        let fails = [("a", "no CO2 in `a`"), ("b", "no CO2 in `b`")];
        let some = FailureReport::new(3, fails);
        assert_eq!((some.failed(), some.all_failed()), (2, false));
        assert_eq!(some.verdict("set.csv", Tolerate), Ok(()));
        assert_eq!(
            some.verdict("set.csv", Strict),
            Err("2 of 3 profiles of set.csv failed (strict: any failed profile is an error): 2 profiles: no CO2 in `a` (profile a and 1 more); nothing was written".into())
        );
        let all = FailureReport::new(2, fails);
        assert!(all.all_failed());
        for p in [Tolerate, Strict] {
            assert_eq!(
                all.verdict("set.csv", p),
                Err("every profile of set.csv failed (2 of 2): 2 profiles: no CO2 in `a` (profile a and 1 more); nothing was written".into())
            );
        }
        let none = FailureReport::new(2, []);
        assert_eq!(none.failed(), 0);
        assert_eq!(none.verdict("set.csv", Strict), Ok(()));
        // Before the run: only strict refuses, on any profile that cannot be run.
        assert_eq!(some.verdict_before_run("set.csv", Tolerate), Ok(()));
        assert_eq!(all.verdict_before_run("set.csv", Tolerate), Ok(()));
        assert_eq!(
            all.verdict_before_run("set.csv", Strict),
            all.verdict("set.csv", Strict)
        );
        assert_eq!(none.verdict_before_run("set.csv", Strict), Ok(()));
        assert_eq!(
            some.verdict_before_run("set.csv", Strict),
            Err("2 of 3 profiles of set.csv cannot be run (strict: any failed profile is an error): 2 profiles: no CO2 in `a` (profile a and 1 more); nothing was run".into())
        );
        // An empty study is not "every profile failed".
        assert!(!FailureReport::new(0, []).all_failed());
    }
}
