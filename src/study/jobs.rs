//! The sweep's campaigns: which there are, which a shard holds, and the order they are started in.

use super::config::StudyConfig;
use super::shard::Shard;

/// One campaign of the sweep: indices into the scenario's regions and the study's lists.
#[derive(Clone, Copy)]
pub(super) struct Job {
    pub(super) region: usize,
    pub(super) layout: usize,
    pub(super) size: usize,
    pub(super) seed: u64,
}

/// Every campaign of the study in config order (region, layout, size, seed), those `shard` holds with their
/// indices, and how many there are in all.
pub(super) fn jobs(
    regions: usize,
    config: &StudyConfig,
    shard: Shard,
) -> (Vec<usize>, Vec<Job>, usize) {
    let mut jobs = Vec::new();
    for region in 0..regions {
        for layout in 0..config.layouts.len() {
            for size in 0..config.sizes.len() {
                for seed in 0..config.seeds {
                    jobs.push(Job {
                        region,
                        layout,
                        size,
                        seed,
                    });
                }
            }
        }
    }
    let total = jobs.len();
    let (held, jobs) = jobs
        .into_iter()
        .enumerate()
        .filter(|(i, _)| shard.holds(*i))
        .unzip();
    (held, jobs, total)
}

/// Orders `jobs` to be started largest first: the campaigns of the most points, a model-based layout's (a
/// selection and one campaign per design) before a fixed one's. In config order the largest came last and the
/// pool ran on one thread through the last of them (a tenth of the default study's wall time); the runs are put
/// back in config order after ([`super::sweep`]'s `in_config_order`), so no output depends on it.
pub(super) fn longest_first(jobs: &mut [Job], config: &StudyConfig) {
    jobs.sort_by_key(|j| {
        std::cmp::Reverse((config.sizes[j.size], config.layouts[j.layout].selects()))
    });
}
