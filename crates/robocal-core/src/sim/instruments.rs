//! Instrument and robot noise of the virtual cell (thesis §2.3–2.4 and Table 2.1; the method
//! digest's §7). The random draws take the caller's generator: the simulator seeds it.

use nalgebra::Vector3;
use rand::Rng;
use rand::distr::Distribution;
use rand_distr::StandardNormal;

/// How the TriCal's auto-centring is simulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Centring {
    /// The loop of the measuring procedure itself (digest §7, thesis §2.3): corrections
    /// computed on the controller's nominal model, a fresh non-repeatable offset at every stop,
    /// stop when the reading is within ε. The recorded pair's error comes out at about the
    /// repeatability (see [`crate::sim::measure`]).
    #[default]
    Loop,
    /// The shortcut: the physical TCP uniform in the ε-ball, the recorded joints those at which
    /// the true model puts the TCP there plus an independent repeatability offset. More
    /// pessimistic: pair errors of ε/√5 ⊕ σ_RP per axis (5.3 µm at the defaults).
    UniformBall,
}

impl Centring {
    /// From its name, `loop` or `uniform-ball`; `None` for anything else.
    pub fn parse(s: &str) -> Option<Centring> {
        match s {
            "loop" => Some(Centring::Loop),
            "uniform-ball" => Some(Centring::UniformBall),
            _ => None,
        }
    }

    /// The name [`Self::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Centring::Loop => "loop",
            Centring::UniformBall => "uniform-ball",
        }
    }
}

/// Noise settings. All lengths in metres. `Default`: loop centring, ε = 10 µm, RP = 10 µm, a
/// tracker of 16 µm + 0.8 µm/m.
#[derive(Clone, Debug, PartialEq)]
pub struct Noise {
    /// How auto-centring is simulated.
    pub centring: Centring,
    /// TriCal auto-centring tolerance ε: the TCP ends uniformly inside a ball of this radius
    /// around the ball centre (thesis §2.3: ε = 10 µm, the robot's repeatability).
    pub epsilon: f64,
    /// The robot's positional repeatability RP (ISO 9283: mean + 3σ of the distances to the
    /// barycentre; 10 µm for the IRB 120). Modelled as an isotropic Gaussian offset between the
    /// pose the joints describe and where the robot physically is, σ = RP / 3.616 per axis.
    pub repeatability: f64,
    /// Laser tracker, 1σ per axis: `tracker_sigma + tracker_sigma_per_m · distance`; this is the
    /// constant part, m.
    pub tracker_sigma: f64,
    /// The tracker σ's growth with the distance from the tracker, m per m.
    pub tracker_sigma_per_m: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Self {
            centring: Centring::Loop,
            epsilon: 10e-6,
            repeatability: 10e-6,
            tracker_sigma: 16e-6,
            tracker_sigma_per_m: 0.8e-6,
        }
    }
}

impl Noise {
    /// No noise at all: every recorded value exact (loop centring, every σ and ε zero).
    pub fn none() -> Self {
        Self {
            centring: Centring::Loop,
            epsilon: 0.0,
            repeatability: 0.0,
            tracker_sigma: 0.0,
            tracker_sigma_per_m: 0.0,
        }
    }

    /// Per-axis σ of the repeatability offset: for an isotropic 3-D Gaussian the distance has
    /// mean σ·√(8/π) and standard deviation σ·√(3 − 8/π), so RP = (1.596 + 3·0.673)·σ = 3.616·σ.
    pub fn repeatability_sigma(&self) -> f64 {
        self.repeatability / ((8.0 / std::f64::consts::PI).sqrt() + 3.0 * (3.0 - 8.0 / std::f64::consts::PI).sqrt())
    }

    /// Where auto-centring leaves the TCP relative to the ball centre, m: uniform in the ε-ball
    /// (a Gaussian direction and a radius ε·U^(1/3)).
    pub fn centring_offset<R: Rng>(&self, rng: &mut R) -> Vector3<f64> {
        let dir = unit_vector(rng);
        let r = self.epsilon * rng.random::<f64>().cbrt();
        dir * r
    }

    /// The robot's non-repeatable offset, m: isotropic Gaussian with σ =
    /// [`Self::repeatability_sigma`] per axis.
    pub(crate) fn repeatability_offset<R: Rng>(&self, rng: &mut R) -> Vector3<f64> {
        gaussian3(rng) * self.repeatability_sigma()
    }

    /// A tracker reading's error at `distance` metres from the tracker, m: isotropic Gaussian with
    /// σ = `tracker_sigma + tracker_sigma_per_m · distance` per axis.
    pub(crate) fn tracker_error<R: Rng>(&self, rng: &mut R, distance: f64) -> Vector3<f64> {
        gaussian3(rng) * (self.tracker_sigma + self.tracker_sigma_per_m * distance)
    }
}

fn gaussian3<R: Rng>(rng: &mut R) -> Vector3<f64> {
    Vector3::new(StandardNormal.sample(rng), StandardNormal.sample(rng), StandardNormal.sample(rng))
}

fn unit_vector<R: Rng>(rng: &mut R) -> Vector3<f64> {
    let v = gaussian3(rng);
    let n = v.norm();
    if n < 1e-12 { Vector3::z() } else { v / n }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn centring_stays_in_the_epsilon_ball_and_fills_it() {
        let n = Noise::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let r: Vec<f64> = (0..20_000).map(|_| n.centring_offset(&mut rng).norm()).collect();
        assert!(r.iter().all(|&x| x <= 10e-6));
        // Uniform in a ball: P(r < ε/2) = 1/8.
        let inner = r.iter().filter(|&&x| x < 5e-6).count() as f64 / r.len() as f64;
        assert!((inner - 0.125).abs() < 0.01, "{inner}");
    }

    /// ISO 9283 repeatability of the simulated offsets comes out at the requested RP.
    #[test]
    fn repeatability_offsets_have_the_requested_rp() {
        let n = Noise::default();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let d: Vec<f64> = (0..50_000).map(|_| n.repeatability_offset(&mut rng).norm()).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (d.len() - 1) as f64).sqrt();
        let rp = mean + 3.0 * sd;
        assert!((rp - 10e-6).abs() < 0.1e-6, "RP {rp}");
    }

    #[test]
    fn tracker_error_grows_with_distance() {
        let n = Noise::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let sd = |d: f64, rng: &mut ChaCha8Rng| {
            let v: Vec<f64> = (0..30_000).map(|_| n.tracker_error(rng, d).x).collect();
            (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
        };
        assert!((sd(0.0, &mut rng) - 16e-6).abs() < 0.5e-6);
        assert!((sd(3.0, &mut rng) - 18.4e-6).abs() < 0.5e-6);
    }
}
