//! The least-squares problem [`super::fit_rod`] hands Levenberg-Marquardt: which unknowns are
//! fitted and where they sit, the rod model they set, the residuals (each centreline point's
//! distance from the model curve, the base prior, the pushing-only penalty) and their Jacobian.

use super::*;

/// Which unknowns are fitted, and where they sit in the parameter vector.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layout {
    pub(super) force: Option<usize>,
    pub(super) position: Option<usize>,
    pub(super) rotation: Option<usize>,
    pub(super) stiffness: Option<usize>,
    pub(super) len: usize,
}

impl Layout {
    pub(super) fn new(settings: &RodFitSettings) -> Self {
        let mut len = 0;
        let mut take = |on: bool, n: usize| {
            on.then(|| {
                len += n;
                len - n
            })
        };
        let force = take(settings.fit_force, 3);
        let position = take(settings.fit_base_position, 3);
        let rotation = take(settings.fit_base_rotation, 3);
        let stiffness = take(settings.fit_stiffness, 1);
        Self {
            force,
            position,
            rotation,
            stiffness,
            len,
        }
    }

    /// Finite-difference step of each unknown.
    pub(super) fn steps(&self) -> Vec<f64> {
        let mut steps = vec![0.0; self.len];
        let mut set = |at: Option<usize>, n: usize, h: f64| {
            if let Some(at) = at {
                steps[at..at + n].iter_mut().for_each(|s| *s = h);
            }
        };
        set(self.force, 3, 1e-6);
        set(self.position, 3, 1e-5);
        set(self.rotation, 3, 1e-6);
        set(self.stiffness, 1, 1e-6);
        steps
    }
}

/// How reconstructed points are paired with the model's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Pairing {
    /// The model's point at the same arc length from the tip.
    ArcFromTip,
    /// The nearest point of the model.
    Nearest,
}

/// The rod for a parameter vector.
pub(super) struct Model {
    pub(super) config: RodConfig,
    pub(super) base: RodBase,
    pub(super) force: Vec3,
}

/// Why a parameter vector gives no shape.
pub(super) enum Unsolved {
    Rod(RodError),
    TooLarge,
}

pub(super) struct Problem<'a> {
    /// The rod with the fit's integration step.
    pub(super) config: RodConfig,
    pub(super) base: &'a RodBase,
    pub(super) target: &'a [Vec3],
    /// Arc length of each target point from the target's last point, mm.
    pub(super) from_tip_mm: Vec<f64>,
    pub(super) tip: Option<Vec3>,
    pub(super) settings: &'a RodFitSettings,
    pub(super) layout: Layout,
    pub(super) pairing: Pairing,
    pub(super) params: DVector<f64>,
    /// The residuals last computed, where, and where the rod's solve there ended.
    pub(super) cache: RefCell<Option<Evaluated>>,
    pub(super) solves: Cell<usize>,
    pub(super) jacobians: Cell<usize>,
    /// The first rod failure met.
    pub(super) failure: RefCell<Option<RodError>>,
    /// The weight of the base prior's rows, mm (`σ·√(k/n)`, [`BasePrior`]); zero until its
    /// stage.
    pub(super) prior_weight_mm: f64,
}

impl Problem<'_> {
    pub(super) fn model(&self, x: &DVector<f64>, config: &RodConfig) -> Model {
        let vec_at = |at: usize| Vec3::new(x[at], x[at + 1], x[at + 2]);
        let force = self
            .layout
            .force
            .map_or(self.settings.initial_force_n, vec_at);
        let mut base = *self.base;
        if let Some(at) = self.layout.position {
            base.position_mm += vec_at(at);
        }
        if let Some(at) = self.layout.rotation {
            let w = vec_at(at);
            let angle = w.norm();
            if angle > 0.0 {
                base.orientation = Mat3::rotation(w / angle, angle) * base.orientation;
            }
        }
        let config = match self.layout.stiffness {
            Some(at) => config
                .clone()
                .with_bending_stiffness(config.bending_stiffness_n_mm2() * x[at].exp()),
            None => config.clone(),
        };
        Model {
            config,
            base,
            force,
        }
    }

    /// The rod at `x`, solved with `config`'s steps, from where a solved rod's solve ended
    /// where `x` is close to that rod's point ([`rod::solve_near`]).
    pub(super) fn solve_with(
        &self,
        x: &DVector<f64>,
        config: &RodConfig,
        near: Option<&NewtonStart>,
    ) -> Result<(Model, RodShape, NewtonStart), Unsolved> {
        let model = self.model(x, config);
        if model.force.norm() > self.settings.max_force_n {
            return Err(Unsolved::TooLarge);
        }
        self.solves.set(self.solves.get() + 1);
        let (shape, end) = rod::solve_near(&model.config, &model.base, model.force, near)
            .map_err(Unsolved::Rod)?;
        Ok((model, shape, end))
    }

    /// Number of residuals: three per point, three for the tip when it counts, one for the
    /// contact constraint when it applies, and the base prior's ([`Self::prior_rows`]).
    pub(super) fn rows(&self) -> usize {
        self.shape_rows() + usize::from(self.pulls()) + self.prior_rows()
    }

    /// The rows of the shape: three per point and three for the tip when it counts.
    pub(super) fn shape_rows(&self) -> usize {
        3 * (self.target.len() + usize::from(self.tip.is_some()))
    }

    /// The base prior's rows: three for a fitted position, three for a fitted rotation's tilt
    /// and one for its roll when the roll has a prior.
    pub(super) fn prior_rows(&self) -> usize {
        let Some(prior) = self.settings.base_prior else {
            return 0;
        };
        3 * usize::from(self.layout.position.is_some())
            + self
                .layout
                .rotation
                .map_or(0, |_| 3 + usize::from(prior.roll_sd_deg.is_some()))
    }

    /// Whether the contact constraint applies (the force is fitted and must push).
    pub(super) fn pulls(&self) -> bool {
        self.settings.pushing_only && self.layout.force.is_some()
    }

    /// The base prior's residuals at `x`, mm ([`BasePrior`]); zero until its stage.
    pub(super) fn prior_residuals(&self, x: &DVector<f64>) -> Vec<f64> {
        let Some(prior) = self.settings.base_prior else {
            return Vec::new();
        };
        let weight = self.prior_weight_mm;
        let vec_at = |at: usize| Vec3::new(x[at], x[at + 1], x[at + 2]);
        let mut rows = Vec::with_capacity(self.prior_rows());
        if let Some(at) = self.layout.position {
            let offset = vec_at(at) * (weight / prior.position_sd_mm.max(1e-9));
            rows.extend(offset.0);
        }
        if let Some(at) = self.layout.rotation {
            let w = vec_at(at);
            let axis = self.base.orientation.column(2);
            let roll = w.dot(axis);
            let tilt = (w - axis * roll) * (weight / prior.tilt_sd_deg.to_radians().max(1e-9));
            rows.extend(tilt.0);
            if let Some(roll_sd) = prior.roll_sd_deg {
                rows.push(roll * weight / roll_sd.to_radians().max(1e-9));
            }
        }
        rows
    }

    pub(super) fn residuals_of(
        &self,
        x: &DVector<f64>,
        shape: &RodShape,
        model: &Model,
    ) -> DVector<f64> {
        let curve = ModelCurve::new(shape, self.settings.proximal_shaft_mm);
        let tip_weight = self.tip.map_or(0.0, |_| self.settings.tip_weight.max(0.0));
        let scale = 1.0 / (self.target.len() as f64 + tip_weight).sqrt();
        let mut r = DVector::zeros(self.rows());
        let length = curve.arc[curve.arc.len() - 1];
        for (k, p) in self.target.iter().enumerate() {
            let paired = match self.pairing {
                Pairing::ArcFromTip => curve.at_arc(length - self.from_tip_mm[k]),
                Pairing::Nearest => curve.nearest(*p),
            };
            let mut d = *p - paired;
            if self.pairing == Pairing::Nearest && paired == curve.points[curve.points.len() - 1] {
                // Beyond the rod's tip only the offset across it counts: the reconstructed tip is
                // its least precise point along the catheter.
                let t = shape.tangents[shape.tangents.len() - 1];
                let along = d.dot(t);
                if along > 0.0 {
                    d = d - t * along;
                }
            }
            for c in 0..3 {
                r[3 * k + c] = d[c] * scale;
            }
        }
        if let Some(tip) = self.tip {
            let d = (tip - shape.tip_mm()) * (tip_weight.sqrt() * scale);
            let at = 3 * self.target.len();
            for c in 0..3 {
                r[at + c] = d[c];
            }
        }
        if self.pulls() {
            let axis = model.base.orientation.column(2);
            let pull_n = model.force.dot(axis).max(0.0);
            r[self.shape_rows()] = PULL_PENALTY_MM_PER_N * pull_n;
        }
        let first = self.shape_rows() + usize::from(self.pulls());
        for (k, v) in self.prior_residuals(x).into_iter().enumerate() {
            r[first + k] = v;
        }
        r
    }

    /// Standard error of the fitted force at `params`, N: `s² (JᵀJ)⁻¹` over the centreline's
    /// (and the tip's) rows, with `s²` their residual variance per degree of freedom (residuals
    /// and Jacobian are scaled by `1/√n` here, which cancels). The contact constraint's row is
    /// left out: this is what the shape says about the force. Points along a centreline are not
    /// independent (they are 1 mm apart and their errors are smooth), so it is a relative
    /// measure; [`crate::reconstruction::physics_force::ForceCombination`] scales it on calibration pairs.
    /// With it, the correlations of the force's errors between axes (x-y, x-z, y-z) from the same
    /// covariance.
    pub(super) fn force_standard_error(&self) -> Option<([f32; 3], [f32; 3])> {
        let at = self.layout.force?;
        let shape_rows = self.shape_rows();
        let r = self
            .evaluate(&self.params)?
            .rows(0, shape_rows)
            .into_owned();
        let j = LeastSquaresProblem::jacobian(self)?
            .rows(0, shape_rows)
            .into_owned();
        let dof = shape_rows
            .checked_sub(self.params.len())
            .filter(|&d| d > 0)?;
        // Scaled residuals r = d/√n: the per-coordinate variance is s² = n‖r‖²/dof and the
        // unscaled JᵀJ is n times this one, so s² (J_uᵀJ_u)⁻¹ = ‖r‖²/dof · (JᵀJ)⁻¹.
        let s2 = r.norm_squared() / dof as f64;
        let covariance = (j.transpose() * &j).try_inverse()? * s2;
        let sd = |c: usize| covariance[(at + c, at + c)].max(0.0).sqrt();
        let correlation = |a: usize, b: usize| {
            let r = covariance[(at + a, at + b)] / (sd(a) * sd(b));
            if r.is_finite() {
                r.clamp(-1.0, 1.0)
            } else {
                0.0
            }
        };
        Some((
            [sd(0), sd(1), sd(2)].map(|v| v as f32),
            [correlation(0, 1), correlation(0, 2), correlation(1, 2)].map(|v| v as f32),
        ))
    }

    /// Residuals at `x`, or `None` where the rod cannot be solved.
    pub(super) fn evaluate(&self, x: &DVector<f64>) -> Option<DVector<f64>> {
        self.evaluated(x).map(|evaluated| evaluated.residuals)
    }

    /// Residuals at `x` and where the rod's solve there ended, or `None` where the rod cannot
    /// be solved.
    pub(super) fn evaluated(&self, x: &DVector<f64>) -> Option<Evaluated> {
        if let Some(evaluated) = &*self.cache.borrow()
            && evaluated.at == *x
        {
            return Some(evaluated.clone());
        }
        match self.solve_with(x, &self.config, None) {
            Ok((model, shape, end)) => {
                let evaluated = Evaluated {
                    at: x.clone(),
                    residuals: self.residuals_of(x, &shape, &model),
                    end,
                };
                *self.cache.borrow_mut() = Some(evaluated.clone());
                Some(evaluated)
            }
            Err(Unsolved::Rod(e)) => {
                self.failure.borrow_mut().get_or_insert(e);
                None
            }
            Err(Unsolved::TooLarge) => None,
        }
    }
}

/// The residuals at one point of the fit.
#[derive(Clone)]
pub(super) struct Evaluated {
    pub(super) at: DVector<f64>,
    pub(super) residuals: DVector<f64>,
    /// Where the solved rod's Newton's method ended there: where the probes of the Jacobian
    /// about that point start theirs.
    pub(super) end: NewtonStart,
}

/// The size of the residual answered for a step where the rod cannot be solved, mm: far worse
/// than any fit, so the step is rejected.
pub(super) const FAILED_STEP_MM: f64 = 1e4;

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.params.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.params.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(
            self.evaluate(&self.params)
                .unwrap_or_else(|| DVector::from_element(self.rows(), FAILED_STEP_MM)),
        )
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.jacobians.set(self.jacobians.get() + 1);
        let x = self.params.clone();
        let Evaluated {
            residuals: r0, end, ..
        } = self.evaluated(&x)?;
        let near = |probe: &DVector<f64>| self.solve_with(probe, &self.config, Some(&end));
        let mut jacobian = DMatrix::zeros(r0.len(), x.len());
        for (j, h) in self.layout.steps().into_iter().enumerate() {
            let mut probe = x.clone();
            probe[j] += h;
            let column = match near(&probe) {
                Ok((model, shape, _)) => (self.residuals_of(&probe, &shape, &model) - &r0) / h,
                Err(_) => {
                    probe[j] = x[j] - h;
                    let (model, shape, _) = near(&probe).ok()?;
                    (&r0 - self.residuals_of(&probe, &shape, &model)) / h
                }
            };
            jacobian.set_column(j, &column);
        }
        Some(jacobian)
    }
}

/// The model's centreline: the straight shaft behind the base, then the rod, with the arc length
/// of each point (negative along the shaft).
pub(super) struct ModelCurve {
    pub(super) points: Vec<Vec3>,
    pub(super) arc: Vec<f64>,
}

impl ModelCurve {
    pub(super) fn new(shape: &RodShape, shaft_mm: f64) -> Self {
        let mut points = Vec::with_capacity(shape.points_mm.len() + 1);
        let mut arc = Vec::with_capacity(shape.points_mm.len() + 1);
        if shaft_mm > 0.0 {
            points.push(shape.points_mm[0] - shape.tangents[0] * shaft_mm);
            arc.push(-shaft_mm);
        }
        points.extend_from_slice(&shape.points_mm);
        arc.extend_from_slice(&shape.arc_mm);
        Self { points, arc }
    }

    /// The point at arc length `s` (clamped to the curve).
    pub(super) fn at_arc(&self, s: f64) -> Vec3 {
        let n = self.points.len();
        let k = self.arc.partition_point(|&a| a < s).clamp(1, n - 1);
        let span = self.arc[k] - self.arc[k - 1];
        let t = if span > 0.0 {
            ((s - self.arc[k - 1]) / span).clamp(0.0, 1.0)
        } else {
            1.0
        };
        self.points[k - 1] + (self.points[k] - self.points[k - 1]) * t
    }

    /// The point nearest to `p`.
    pub(super) fn nearest(&self, p: Vec3) -> Vec3 {
        let mut best = self.points[0];
        let mut best_d2 = f64::INFINITY;
        for w in self.points.windows(2) {
            let (a, b) = (w[0], w[1]);
            let ab = b - a;
            let len2 = ab.dot(ab);
            let t = if len2 > 0.0 {
                ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = a + ab * t;
            let d = p - q;
            let d2 = d.dot(d);
            if d2 < best_d2 {
                best_d2 = d2;
                best = q;
            }
        }
        best
    }
}
