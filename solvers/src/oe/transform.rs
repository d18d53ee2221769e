//! The change of variables that keeps a bounded parameter inside its bounds during an
//! unconstrained minimisation (MINUIT, lmfit): θ = lb + (ub − lb)(1 + sin u)/2 for two
//! bounds, θ = lb − 1 + √(u² + 1) for a lower one, θ = ub + 1 − √(u² + 1) for an upper one.

use wheelid_core::BoundState;

/// The change of variables that keeps one parameter inside its bounds.
#[derive(Debug, Clone, Copy)]
pub(super) enum Transform {
    Free,
    Both(f64, f64),
    Lower(f64),
    Upper(f64),
}

impl Transform {
    pub(super) fn new((lo, hi): (f64, f64)) -> Self {
        match (lo.is_finite(), hi.is_finite()) {
            (true, true) => Self::Both(lo, hi),
            (true, false) => Self::Lower(lo),
            (false, true) => Self::Upper(hi),
            (false, false) => Self::Free,
        }
    }
    pub(super) fn theta(self, u: f64) -> f64 {
        match self {
            Self::Free => u,
            Self::Both(lo, hi) => lo + (hi - lo) * (1.0 + u.sin()) / 2.0,
            Self::Lower(lo) => lo - 1.0 + (u * u + 1.0).sqrt(),
            Self::Upper(hi) => hi + 1.0 - (u * u + 1.0).sqrt(),
        }
    }
    pub(super) fn dtheta_du(self, u: f64) -> f64 {
        match self {
            Self::Free => 1.0,
            Self::Both(lo, hi) => (hi - lo) * u.cos() / 2.0,
            Self::Lower(_) => u / (u * u + 1.0).sqrt(),
            Self::Upper(_) => -u / (u * u + 1.0).sqrt(),
        }
    }
    /// Whether u puts θ on a bound: where the transform is flat (dθ/du ≈ 0), θ is within
    /// ~1e-8 of the bound's scale and the data no longer move it.
    pub(super) fn bound_state(self, u: f64) -> BoundState {
        match self {
            Self::Free => BoundState::Free,
            Self::Both(..) if u.cos().abs() < 1e-4 => {
                if u.sin() < 0.0 {
                    BoundState::AtLower
                } else {
                    BoundState::AtUpper
                }
            }
            Self::Lower(_) if u.abs() < 1e-4 => BoundState::AtLower,
            Self::Upper(_) if u.abs() < 1e-4 => BoundState::AtUpper,
            _ => BoundState::Free,
        }
    }
    /// u for θ; θ is first moved a hair inside the bounds so that the derivative is not 0.
    pub(super) fn u(self, theta: f64) -> f64 {
        match self {
            Self::Free => theta,
            Self::Both(lo, hi) => {
                let x = (2.0 * (theta - lo) / (hi - lo) - 1.0).clamp(-1.0 + 1e-9, 1.0 - 1e-9);
                x.asin()
            }
            Self::Lower(lo) => ((theta - lo + 1.0).max(1.0 + 1e-9).powi(2) - 1.0).sqrt(),
            Self::Upper(hi) => ((hi - theta + 1.0).max(1.0 + 1e-9).powi(2) - 1.0).sqrt(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_round_trip_and_stay_inside() {
        for t in [
            Transform::Free,
            Transform::Both(-1.0, 3.0),
            Transform::Lower(0.5),
            Transform::Upper(-2.0),
        ] {
            for x in [0.7f64, 1.9, -0.3] {
                let x = match t {
                    Transform::Lower(lo) => lo + x.abs(),
                    Transform::Upper(hi) => hi - x.abs(),
                    _ => x,
                };
                let u = t.u(x);
                approx::assert_relative_eq!(t.theta(u), x, max_relative = 1e-12);
                let h = 1e-6;
                let fd = (t.theta(u + h) - t.theta(u - h)) / (2.0 * h);
                approx::assert_relative_eq!(t.dtheta_du(u), fd, max_relative = 1e-6);
            }
            // On a bound the transform is flat and the state says so; inside it does not.
            match t {
                Transform::Both(lo, hi) => {
                    assert_eq!(t.bound_state(t.u(hi)), BoundState::AtUpper);
                    assert_eq!(t.bound_state(t.u(lo)), BoundState::AtLower);
                    assert_eq!(t.bound_state(t.u(0.5 * (lo + hi))), BoundState::Free);
                }
                Transform::Lower(lo) => {
                    assert_eq!(t.bound_state(t.u(lo)), BoundState::AtLower);
                    assert_eq!(t.bound_state(t.u(lo + 1e-3)), BoundState::Free);
                }
                Transform::Upper(hi) => {
                    assert_eq!(t.bound_state(t.u(hi)), BoundState::AtUpper);
                    assert_eq!(t.bound_state(t.u(hi - 1e-3)), BoundState::Free);
                }
                Transform::Free => assert_eq!(t.bound_state(0.0), BoundState::Free),
            }
            for u in [-40.0, -1.0, 0.0, 2.0, 123.0] {
                let x = t.theta(u);
                match t {
                    Transform::Both(lo, hi) => assert!((lo..=hi).contains(&x)),
                    Transform::Lower(lo) => assert!(x >= lo),
                    Transform::Upper(hi) => assert!(x <= hi),
                    Transform::Free => {}
                }
            }
        }
    }
}
