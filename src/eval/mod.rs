//! The paper's experiments (sect. 8) and trajectory metrics.

pub mod accuracy;
pub mod bound;
pub mod demo;
pub mod drift;
pub mod matching;
pub mod metrics;
pub mod pair_bound;
pub mod path_bound;
pub mod real;
pub mod run;
#[cfg(test)]
pub(crate) mod test_scenes;
pub mod true_segments;
