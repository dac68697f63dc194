//! What the simulator's range noise figure means: a Gaussian's standard deviation (ours), or
//! the full width of uniform noise, one reading of the paper's "a range of about 1 cm"
//! (appendix C: the readings of a SICK LMS 200 on a flat wall spread over about 1 cm, peak to
//! peak).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal, StandardUniform};

/// How a noise figure `noise` \[m\] turns into range errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum NoiseModel {
    /// Gaussian with standard deviation `noise`.
    #[default]
    Gaussian,
    /// Uniform over `noise` peak to peak (+-noise/2), a standard deviation of
    /// `noise / sqrt(12)`: the paper's "range of about 1 cm" read as the readings' spread.
    #[value(alias = "paper")]
    Uniform,
}

impl NoiseModel {
    /// The standard deviation of the range errors for the noise figure `noise` \[m\].
    pub fn sigma(self, noise: f64) -> f64 {
        match self {
            NoiseModel::Gaussian => noise,
            NoiseModel::Uniform => noise / 12f64.sqrt(),
        }
    }

    /// One range error \[m\].
    pub fn draw<R: Rng + ?Sized>(self, noise: f64, rng: &mut R) -> f64 {
        match self {
            NoiseModel::Gaussian => {
                let z: f64 = StandardNormal.sample(rng);
                noise * z
            }
            NoiseModel::Uniform => {
                let u: f64 = StandardUniform.sample(rng);
                noise * (u - 0.5)
            }
        }
    }
}

impl std::fmt::Display for NoiseModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NoiseModel::Gaussian => "gaussian",
            NoiseModel::Uniform => "uniform",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;

    /// Drawn errors have the stated spread: the sample standard deviation within 2% of
    /// `sigma`, and uniform errors never beyond half the width.
    #[test]
    fn draws_match_the_stated_sigma_and_width() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for model in [NoiseModel::Gaussian, NoiseModel::Uniform] {
            let n = 40_000;
            let draws: Vec<f64> = (0..n).map(|_| model.draw(0.05, &mut rng)).collect();
            let mean = draws.iter().sum::<f64>() / n as f64;
            let sd = (draws.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
            assert!(mean.abs() < 0.001, "{model}: mean {mean}");
            let want = model.sigma(0.05);
            assert!((sd / want - 1.0).abs() < 0.02, "{model}: sd {sd} vs {want}");
            if model == NoiseModel::Uniform {
                assert!(draws.iter().all(|e| e.abs() <= 0.025));
                let max = draws.iter().fold(0.0f64, |m, e| m.max(e.abs()));
                assert!(max > 0.0249, "{max}");
            }
        }
    }

    #[test]
    fn uniform_sigma_is_width_over_root_twelve() {
        assert_eq!(NoiseModel::Gaussian.sigma(0.1), 0.1);
        assert!((NoiseModel::Uniform.sigma(0.01) - 0.002_886_751_345_948_129).abs() < 1e-15);
    }
}
