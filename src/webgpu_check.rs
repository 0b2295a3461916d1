//! The WebGPU result check (issue #13). WebGPU stacks have returned stale or wrong data without
//! any error (cubecl #1641: a shader that fails validation in the browser is skipped silently),
//! so before the page trusts WebGPU with the user's pairs it runs the weights on one fixed twin
//! pair on WebGPU and on the CPU path and compares the two results. Beyond the tolerances below
//! the page uses the CPU and says why in the model bar.
//!
//! The tolerances are far above the float differences of two correct backends (different
//! summation orders: about 10⁻⁵ on masks and forces here) and far below what a wrong kernel or
//! stale buffer gives.

use hnet_twin::simulator::sensor_plate::ContactError;
use hnet_units::TipForce;

use crate::twin_live::{TwinControls, XrayBackground};
use crate::workspace::LabeledPair;

/// Largest difference of a catheter probability (0-1) between WebGPU and the CPU.
pub const MASK_TOLERANCE: f32 = 0.01;

/// Largest difference of a tip-force component between WebGPU and the CPU, newtons.
pub const FORCE_TOLERANCE_N: f32 = 0.001;

/// The pair both backends run on: the twin tab's first pair (default sliders, phantom
/// background), the same on every machine.
pub fn check_pair() -> Result<LabeledPair, ContactError> {
    TwinControls::default().render("webgpu-check".into(), &XrayBackground::phantom())
}

/// What one backend gave on the check pair: both masks (probabilities) and the force (N).
#[derive(Debug, Clone, Copy)]
pub struct Output<'a> {
    /// View A's and view B's catheter probabilities.
    pub masks: [&'a [f32]; 2],
    /// Tip force, newtons.
    pub force_n: TipForce,
}

/// The largest differences between two backends' outputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Difference {
    /// Largest difference of a pixel's catheter probability (infinite when a value is not
    /// finite or the masks differ in size).
    pub mask: f32,
    /// Largest difference of a force component, newtons (infinite when one is not finite).
    pub force_n: f32,
}

/// The largest absolute difference of paired values; infinite if any is not finite.
fn largest(a: impl IntoIterator<Item = f32>, b: impl IntoIterator<Item = f32>) -> f32 {
    a.into_iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .map(|d| if d.is_finite() { d } else { f32::INFINITY })
        .fold(0.0, f32::max)
}

impl Difference {
    /// The differences between the CPU's output and WebGPU's.
    pub fn between(cpu: Output, webgpu: Output) -> Self {
        let mask = if cpu
            .masks
            .iter()
            .zip(&webgpu.masks)
            .any(|(a, b)| a.len() != b.len())
        {
            f32::INFINITY
        } else {
            cpu.masks
                .iter()
                .zip(&webgpu.masks)
                .map(|(a, b)| largest(a.iter().copied(), b.iter().copied()))
                .fold(0.0, f32::max)
        };
        Self {
            mask,
            force_n: largest(cpu.force_n.newtons(), webgpu.force_n.newtons()),
        }
    }

    /// Whether both differences are within the tolerances times `scale`.
    pub fn within(&self, scale: f64) -> bool {
        f64::from(self.mask) <= f64::from(MASK_TOLERANCE) * scale
            && f64::from(self.force_n) <= f64::from(FORCE_TOLERANCE_N) * scale
    }

    /// The differences for the model bar.
    pub fn text(&self) -> String {
        format!(
            "masks within {:.2e}, force within {:.2e} N of the CPU on a check pair",
            self.mask, self.force_n
        )
    }

    /// Why WebGPU is not used.
    pub fn refusal(&self, scale: f64) -> String {
        format!(
            "WebGPU's result on a check pair differs from the CPU's (masks by up to {:.2e}, force \
             by {:.2e} N; tolerated: {:.2e} and {:.2e} N), so the CPU is used",
            self.mask,
            self.force_n,
            f64::from(MASK_TOLERANCE) * scale,
            f64::from(FORCE_TOLERANCE_N) * scale
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_float_differences_pass_and_wrong_or_stale_results_do_not() {
        let cpu = [vec![0.1f32, 0.9, 0.5], vec![0.0, 1.0, 0.2]];
        let force = TipForce::new(0.1, -0.05, 0.2);
        fn output(masks: &[Vec<f32>; 2], force_n: TipForce) -> Output<'_> {
            Output {
                masks: [&masks[0], &masks[1]],
                force_n,
            }
        }
        let close = [vec![0.10001f32, 0.9, 0.5], vec![0.0, 0.99999, 0.2]];
        let same = Difference::between(
            output(&cpu, force),
            output(&close, TipForce::new(0.10002, -0.05, 0.2)),
        );
        assert!(same.within(1.0), "{same:?}");
        assert!(
            same.text().starts_with("masks within 1.00e-5"),
            "{}",
            same.text()
        );
        assert!(!same.within(-1.0));
        // Stale zeros, a NaN, a short buffer.
        let zeros = [vec![0.0f32; 3], vec![0.0; 3]];
        let stale = Difference::between(output(&cpu, force), output(&zeros, TipForce::ZERO));
        assert!(!stale.within(1.0));
        assert!(
            stale.refusal(1.0).contains("masks by up to 1.00e0"),
            "{}",
            stale.refusal(1.0)
        );
        let nan = Difference::between(
            output(&cpu, force),
            output(&cpu, TipForce::new(f32::NAN, 0.0, 0.0)),
        );
        assert_eq!(nan.force_n, f32::INFINITY);
        let short = [vec![0.1f32], vec![0.0]];
        assert_eq!(
            Difference::between(output(&cpu, force), output(&short, force)).mask,
            f32::INFINITY
        );
    }

    #[test]
    fn the_check_pair_is_the_same_every_time() {
        assert_eq!(check_pair().unwrap(), check_pair().unwrap());
    }
}
