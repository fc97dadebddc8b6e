//! The elementary functions the simulator and its players use (sine, cosine, arc cosine, arc
//! tangent, exponential, logarithm, tanh), computed by the `libm` crate's portable Rust code rather
//! than the platform's C library.
//!
//! Rust's `f64::sin`, `exp`, `acos`, … call the system's libm, which differs between platforms
//! (glibc, macOS, musl) and, within glibc, between CPUs: glibc picks an FMA or an SSE2 build of
//! each function when the program starts, and the two disagree in the last bit for some
//! arguments: the goldens (`agents/tests/goldens/`) played on an emulated CPU without FMA diverged
//! from there. These functions give the same bits on every machine; basic arithmetic and `sqrt` are
//! IEEE-exact everywhere already.
//! Quaternions built from an angle go through here too ([`quat_from_scaled_axis`]), since
//! nalgebra's constructors call `f64::sin_cos`.
//!
//! A change of any of these (the `libm` release included) alters trajectories: bump
//! [`crate::SIM_VERSION`].

use nalgebra::{Quaternion, Unit, UnitQuaternion, Vector3};

/// sin x.
#[inline]
pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}

/// cos x.
#[inline]
pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}

/// (sin x, cos x).
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// arccos x (NaN outside [−1, 1]).
#[inline]
pub fn acos(x: f64) -> f64 {
    libm::acos(x)
}

/// The angle of (x, y) from the x axis, in (−π, π].
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}

/// eˣ.
#[inline]
pub fn exp(x: f64) -> f64 {
    libm::exp(x)
}

/// eˣ − 1, accurate near 0.
#[inline]
pub fn exp_m1(x: f64) -> f64 {
    libm::expm1(x)
}

/// ln x.
#[inline]
pub fn ln(x: f64) -> f64 {
    libm::log(x)
}

/// tanh x.
#[inline]
pub fn tanh(x: f64) -> f64 {
    libm::tanh(x)
}

/// The rotation by `angle` about the unit `axis` (nalgebra's `from_axis_angle`, on [`sin_cos`]).
#[inline]
pub fn quat_from_axis_angle(axis: &Unit<Vector3<f64>>, angle: f64) -> UnitQuaternion<f64> {
    let (s, c) = sin_cos(0.5 * angle);
    UnitQuaternion::new_unchecked(Quaternion::from_parts(c, axis.into_inner() * s))
}

/// The rotation by |v| about v / |v|, the identity for v = 0 (nalgebra's `from_scaled_axis`, on
/// [`sin_cos`]).
#[inline]
pub fn quat_from_scaled_axis(v: Vector3<f64>) -> UnitQuaternion<f64> {
    match Unit::try_new_and_get(v, 0.0) {
        Some((axis, angle)) => quat_from_axis_angle(&axis, angle),
        None => UnitQuaternion::identity(),
    }
}

/// The shortest rotation taking the direction of `a` to that of `b` (nalgebra's
/// `rotation_between`, on [`acos`] and [`sin_cos`]): the identity when either is zero or they point
/// the same way, `None` when they are opposite (no unique axis).
pub fn quat_rotation_between(a: &Vector3<f64>, b: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let (Some(na), Some(nb)) = (Unit::try_new(*a, 0.0), Unit::try_new(*b, 0.0)) else {
        return Some(UnitQuaternion::identity());
    };
    let cos = na.dot(&nb);
    match Unit::try_new(na.cross(&nb), f64::EPSILON) {
        Some(_) if cos <= -1.0 => None,
        Some(_) if cos >= 1.0 => Some(UnitQuaternion::identity()),
        Some(axis) => Some(quat_from_axis_angle(&axis, acos(cos))),
        None if cos < 0.0 => None,
        None => Some(UnitQuaternion::identity()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within a few ulps of the platform's functions (which may differ from these in the last
    /// bit), and exact where the closed form is.
    #[test]
    fn the_functions_agree_with_the_platforms_to_a_few_ulps() {
        let close = |a: f64, b: f64| (a - b).abs() <= 4.0 * f64::EPSILON * b.abs().max(1e-300);
        for i in -200..=200 {
            let x = i as f64 * 0.0371;
            assert!(close(sin(x), x.sin()), "sin {x}");
            assert!(close(cos(x), x.cos()), "cos {x}");
            assert_eq!(sin_cos(x), (sin(x), cos(x)), "sin_cos {x}");
            assert!(close(exp(x), x.exp()), "exp {x}");
            assert!(close(exp_m1(x), x.exp_m1()), "exp_m1 {x}");
            assert!(close(tanh(x), x.tanh()), "tanh {x}");
            assert!(close(atan2(x, 1.3), x.atan2(1.3)), "atan2 {x}");
            let u = i as f64 / 200.0;
            assert!(close(acos(u), u.acos()), "acos {u}");
            if x > 0.0 {
                assert!(close(ln(x), x.ln()), "ln {x}");
            }
        }
        assert_eq!(
            (sin(0.0), cos(0.0), exp(0.0), ln(1.0)),
            (0.0, 1.0, 1.0, 0.0)
        );
        assert!(acos(1.5).is_nan());
    }

    #[test]
    fn quaternions_are_nalgebras_rotations() {
        let q0 = quat_from_scaled_axis(Vector3::zeros());
        assert_eq!(q0, UnitQuaternion::identity());
        for v in [
            Vector3::new(0.3, -1.2, 0.7),
            Vector3::new(0.0, 0.0, std::f64::consts::PI),
            Vector3::new(1e-9, 0.0, 0.0),
        ] {
            let ours = quat_from_scaled_axis(v);
            let theirs = UnitQuaternion::from_scaled_axis(v);
            assert!(ours.angle_to(&theirs) < 1e-14, "{v:?}");
            assert!((ours.quaternion().norm() - 1.0).abs() < 1e-15);
        }
        for (a, b) in [
            (Vector3::z(), Vector3::new(0.2, -0.5, 0.8)),
            (Vector3::new(1.0, 2.0, 3.0), Vector3::new(3.0, 1.0, 2.0)),
        ] {
            let q = quat_rotation_between(&a, &b).unwrap();
            let theirs = UnitQuaternion::rotation_between(&a, &b).unwrap();
            assert!(q.angle_to(&theirs) < 1e-14);
            assert!((q * a.normalize() - b.normalize()).norm() < 1e-15);
        }
        assert_eq!(quat_rotation_between(&Vector3::z(), &-Vector3::z()), None);
        assert_eq!(
            quat_rotation_between(&Vector3::z(), &(2.0 * Vector3::z())),
            Some(UnitQuaternion::identity())
        );
        let axis = Vector3::y_axis();
        let q = quat_from_axis_angle(&axis, std::f64::consts::FRAC_PI_2);
        let x = q * Vector3::x();
        assert!((x - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-15, "{x:?}");
    }
}
