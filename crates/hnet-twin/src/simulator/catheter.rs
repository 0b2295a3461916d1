//! The catheter's visible design: shaft, electrodes, their X-ray attenuation and their colour.

use serde::{Deserialize, Serialize};

/// A ring electrode, placed by its distal edge's distance from the tip.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RingElectrode {
    /// Distance from the catheter tip to the ring's distal edge, mm.
    pub from_tip_mm: f64,
    /// Ring width along the shaft, mm.
    pub width_mm: f64,
}

/// How the catheter looks to the camera and to X-rays.
///
/// The default is a 7 Fr ablation catheter: 3.5 mm tip electrode and three 1 mm ring electrodes
/// with 2-5-2 mm spacing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CatheterDesign {
    /// Tip electrode length, mm.
    pub tip_electrode_mm: f64,
    /// Ring electrodes proximal to the tip.
    pub rings: Vec<RingElectrode>,
    /// Effective linear attenuation of the polymer shaft (with its braid), 1/mm. Faint: a
    /// 2.33 mm chord transmits about 83 %.
    pub shaft_attenuation_per_mm: f64,
    /// Effective linear attenuation of the platinum-iridium electrodes (thin-walled shells
    /// averaged over the section), 1/mm. Dark: a 2.33 mm chord transmits about 4 %.
    pub electrode_attenuation_per_mm: f64,
    /// Shaft colour under the bench's lights, linear RGB in [0, 1].
    pub shaft_colour: [f32; 3],
    /// Electrode colour, linear RGB in [0, 1].
    pub electrode_colour: [f32; 3],
}

impl Default for CatheterDesign {
    fn default() -> Self {
        Self {
            tip_electrode_mm: 3.5,
            rings: vec![
                RingElectrode {
                    from_tip_mm: 5.5,
                    width_mm: 1.0,
                },
                RingElectrode {
                    from_tip_mm: 11.5,
                    width_mm: 1.0,
                },
                RingElectrode {
                    from_tip_mm: 14.5,
                    width_mm: 1.0,
                },
            ],
            shaft_attenuation_per_mm: 0.08,
            electrode_attenuation_per_mm: 1.4,
            shaft_colour: [0.10, 0.22, 0.45],
            electrode_colour: [0.78, 0.78, 0.80],
        }
    }
}

impl CatheterDesign {
    /// Whether the point at `from_tip_mm` from the tip lies on an electrode.
    pub fn is_electrode(&self, from_tip_mm: f64) -> bool {
        from_tip_mm <= self.tip_electrode_mm
            || self
                .rings
                .iter()
                .any(|r| (r.from_tip_mm..=r.from_tip_mm + r.width_mm).contains(&from_tip_mm))
    }

    /// Linear attenuation at `from_tip_mm` from the tip, 1/mm.
    pub fn attenuation_per_mm(&self, from_tip_mm: f64) -> f64 {
        if self.is_electrode(from_tip_mm) {
            self.electrode_attenuation_per_mm
        } else {
            self.shaft_attenuation_per_mm
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn electrodes_sit_where_designed() {
        let c = CatheterDesign::default();
        assert!(c.is_electrode(0.0) && c.is_electrode(3.5));
        assert!(!c.is_electrode(4.0));
        assert!(c.is_electrode(6.0));
        assert!(!c.is_electrode(9.0));
        assert!(c.is_electrode(15.0));
        assert!(!c.is_electrode(20.0));
        // Transmission through the full 2.33 mm section.
        let t = |mu: f64| (-mu * 2.33).exp();
        assert!((0.8..0.9).contains(&t(c.shaft_attenuation_per_mm)));
        assert!(t(c.electrode_attenuation_per_mm) < 0.06);
    }
}
