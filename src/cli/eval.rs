//! `levelscan eval ...`: the paper's experiments.

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum EvalCommand {}

pub fn run(c: EvalCommand) -> anyhow::Result<()> {
    match c {}
}
