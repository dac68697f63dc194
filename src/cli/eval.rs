//! `levelscan eval ...`: the paper's experiments (sect. 8).

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum EvalCommand {
    /// Table I and Fig. 6: attitude accuracy over random poses (sect. 8.1).
    Accuracy(super::eval_accuracy::Args),
    /// Figs. 8-10 and 12: matching raw, level and leveled scans, pairwise and metascan (sect. 8.2).
    Matching(super::eval_matching::MatchingArgs),
    /// Pairwise matching on real CARMEN logs with perturbed odometry, scored by RPE.
    Real(super::eval_matching::RealArgs),
    /// Plots of one run: roll and pitch over time against the truth, position error along it.
    Run(super::eval_run::Args),
}

pub fn run(c: EvalCommand) -> anyhow::Result<()> {
    match c {
        EvalCommand::Accuracy(a) => super::eval_accuracy::run(a),
        EvalCommand::Matching(a) => super::eval_matching::run_matching(a),
        EvalCommand::Real(a) => super::eval_matching::run_real(a),
        EvalCommand::Run(a) => super::eval_run::run(a),
    }
}
