//! Not written yet.

#[derive(clap::Args, Debug)]
pub struct MatchingArgs {}

#[derive(clap::Args, Debug)]
pub struct RealArgs {}

pub fn run_matching(_args: MatchingArgs) -> anyhow::Result<()> {
    anyhow::bail!("this command is not implemented yet")
}

pub fn run_real(_args: RealArgs) -> anyhow::Result<()> {
    anyhow::bail!("this command is not implemented yet")
}
