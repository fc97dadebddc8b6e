//! Tendon wrapping over spheres and cylinders, with MuJoCo's semantics (its `mju_wrap`): between two path points, a tendon that would cut through the geom goes
//! around it instead — straight to a tangent point, along the surface (a great-circle arc on a
//! sphere, a helix on a cylinder), straight from the second tangent point. A side site picks the
//! side; a side site inside the geom makes the path touch the surface at one point (the "inside"
//! wrap, found by Newton's method).
//!
//! Everything happens in the geom's frame, in the plane of the wrap: the sphere's plane through
//! its centre and both end points, the cylinder's cross-section (its height added afterwards).
//! Pure functions of their arguments; no allocation.

use nalgebra::{Matrix3, Vector2, Vector3};

type V2 = Vector2<f64>;
type V3 = Vector3<f64>;

/// MuJoCo's `mjMINVAL`: below this a length or a determinant counts as zero.
pub const MINVAL: f64 = 1e-15;

/// The shape a tendon wraps over (the geom's radius is its `size[0]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WrapShape {
    /// Wraps along a great circle.
    Sphere,
    /// Wraps along a helix about the local z axis.
    Cylinder,
}

/// A wrap that happened: the two tangent points (world frame; equal for an inside wrap) and the
/// length of the path along the surface between them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wrapped {
    /// Where the path meets the surface, coming from the first end, and where it leaves it.
    pub points: [V3; 2],
    /// Length along the surface, m (0 for an inside wrap).
    pub length: f64,
}

/// MuJoCo's `mju_normalize` for 2-vectors: unit length, or (1, 0) for a vector shorter than MINVAL.
fn unit2(v: V2) -> V2 {
    let n = v.norm();
    if n < MINVAL {
        V2::new(1.0, 0.0)
    } else {
        v * (1.0 / n)
    }
}

/// MuJoCo's `mju_normalize3`: unit length, or (1, 0, 0) for a vector shorter than MINVAL; also
/// returns the length.
pub fn unit3(v: V3) -> (V3, f64) {
    let n = v.norm();
    if n < MINVAL {
        (V3::new(1.0, 0.0, 0.0), n)
    } else {
        (v * (1.0 / n), n)
    }
}

/// Whether the segments `a0–a1` and `b0–b1` cross (parallel ones never do).
fn segments_cross(a0: V2, a1: V2, b0: V2, b1: V2) -> bool {
    let det = (b1.y - b0.y) * (a1.x - a0.x) - (b1.x - b0.x) * (a1.y - a0.y);
    if det.abs() < MINVAL {
        return false;
    }
    let s = ((b1.x - b0.x) * (a0.y - b0.y) - (b1.y - b0.y) * (a0.x - b0.x)) / det;
    let t = ((a1.x - a0.x) * (a0.y - b0.y) - (a1.y - a0.y) * (a0.x - b0.x)) / det;
    (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t)
}

/// Arc length on the circle of `radius` from `p0` to `p1`: the short way round, or the long way
/// when the turn from `p0` to `p1` goes against the chosen solution's direction (`second`).
fn arc_length(p0: V2, p1: V2, second: bool, radius: f64) -> f64 {
    let cos = unit2(p0).dot(&unit2(p1)).clamp(-1.0, 1.0);
    let mut angle = crate::math::acos(cos);
    let turn = p0.y * p1.x - p0.x * p1.y;
    if (turn > 0.0 && second) || (turn < 0.0 && !second) {
        angle = 2.0 * std::f64::consts::PI - angle;
    }
    radius * angle
}

/// The sign of `x` as -1, 0 or 1 (0 for ±0, unlike `f64::signum`).
fn sign(x: f64) -> i8 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// `a × b` in the plane.
fn cross2(a: &V2, b: &V2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Wrap in the plane around the circle of `radius` at the origin, from `ends[0]` to `ends[1]`.
///
/// With a side point `side`: the path goes round the far side of the circle when the side point is
/// behind the centre as seen from the straight segment (its opposite direction lies in the wedge
/// between the two ends), else round the near side — and the near side is a wrap only when the
/// segment cuts the circle. Without one: the shorter way, when the segment cuts the circle. `None`
/// when the path stays straight, when an end is inside the circle, or when the tangent lines would
/// cross. Returns the tangent points and the arc length.
///
/// This side rule is MuJoCo 4.0's as measured on thousands of random cases (MuJoCo's published
/// `wrap_circle` before 4.0 scored the two candidates by the direction of their chord's midpoint
/// instead); the tests pin it against MuJoCo-generated cases.
pub fn wrap_circle(ends: [V2; 2], side: Option<V2>, radius: f64) -> Option<([V2; 2], f64)> {
    let [e0, e1] = ends;
    let (sq0, sq1, sqr) = (e0.norm_squared(), e1.norm_squared(), radius * radius);
    if sq0 < sqr || sq1 < sqr || radius < MINVAL {
        return None;
    }
    let dif = e1 - e0;
    let dd = dif.norm_squared();
    if dd < MINVAL {
        return None;
    }
    // The segment's point nearest the centre: outside the circle means the segment misses it.
    let a = (-dif.dot(&e0) / dd).clamp(0.0, 1.0);
    let misses = (e0 + dif * a).norm_squared() > sqr;
    let turn = sign(cross2(&e0, &e1));
    let behind = side.map(|s| {
        let away = -s;
        sign(cross2(&e0, &away)) == turn && sign(cross2(&away, &e1)) == turn
    });
    if misses && behind != Some(true) {
        return None;
    }
    let (r0, r1) = ((sq0 - sqr).sqrt(), (sq1 - sqr).sqrt());
    // The two candidate pairs of tangent points: the first goes clockwise round the centre from
    // `e0` to `e1`, the second counter-clockwise.
    let candidate = |sgn: f64| -> [V2; 2] {
        [
            V2::new(
                (e0.x * sqr + sgn * radius * e0.y * r0) / sq0,
                (e0.y * sqr - sgn * radius * e0.x * r0) / sq0,
            ),
            V2::new(
                (e1.x * sqr - sgn * radius * e1.y * r1) / sq1,
                (e1.y * sqr + sgn * radius * e1.x * r1) / sq1,
            ),
        ]
    };
    let sols = [candidate(1.0), candidate(-1.0)];
    let i = match behind {
        // Ends in line through the centre: no wedge; the way round nearer the side point.
        Some(_) if turn == 0 => {
            let toward = |t: &[V2; 2]| unit2(t[0] + t[1]).dot(&side.unwrap_or_default());
            if toward(&sols[0]) > toward(&sols[1]) {
                0
            } else {
                1
            }
        }
        // The far side is the way round that does not pass through the ends' wedge.
        Some(behind) => {
            let far = if turn < 0 { 1 } else { 0 };
            if behind {
                far
            } else {
                1 - far
            }
        }
        None => {
            let goodness = |t: &[V2; 2]| -> f64 {
                if segments_cross(e0, t[0], e1, t[1]) {
                    -10000.0
                } else {
                    -(t[0] - t[1]).norm_squared()
                }
            };
            if goodness(&sols[0]) > goodness(&sols[1]) {
                0
            } else {
                1
            }
        }
    };
    let t = sols[i];
    if segments_cross(e0, t[0], e1, t[1]) {
        return None;
    }
    Some((t, arc_length(t[0], t[1], i == 1, radius)))
}

/// The inside wrap: the point of the circle through which the shortest path from `ends[0]` to
/// `ends[1]` passes when it must touch the circle (the side site is inside the geom). `None` when
/// an end is inside the circle or the straight segment cuts into it (the path then stays
/// straight), as MuJoCo.
///
/// The point minimises the path's length over the arc between the two ends' directions; we find
/// it by safeguarded Newton on the length's derivative, to round-off. MuJoCo 4.0 solves the same
/// problem to a residual of about 1e-6 (its point up to ~1e-7 of the radius from this one; measured
/// on random cases); earlier MuJoCo releases fell back to the point between the ends' directions
/// when the segment passed just outside the circle, which 4.0 no longer does.
pub fn wrap_inside(ends: [V2; 2], radius: f64) -> Option<V2> {
    let [e0, e1] = ends;
    let (len0, len1) = (e0.norm(), e1.norm());
    let dif = e1 - e0;
    let dd = dif.norm_squared();
    if len0 <= radius || len1 <= radius || radius < MINVAL || len0 < MINVAL || len1 < MINVAL {
        return None;
    }
    if dd > MINVAL {
        let a = -dif.dot(&e0) / dd;
        if a > 0.0 && a < 1.0 && (e0 + dif * a).norm() <= radius {
            return None;
        }
    }
    // A frame with e0 along x and e1 in the upper half plane: the arc is θ ∈ [0, G].
    let ax = e0 / len0;
    let mut ay = V2::new(-ax.y, ax.x);
    if cross2(&e0, &e1) < 0.0 {
        ay = -ay;
    }
    let (p0, p1) = (V2::new(len0, 0.0), V2::new(e1.dot(&ax), e1.dot(&ay)));
    let g = crate::math::atan2(p1.y, p1.x);
    let theta = if g < 1e-12 {
        0.5 * g
    } else {
        shortest_touch(p0, p1, g, radius)
    };
    let (s, c) = crate::math::sin_cos(theta);
    Some((ax * c + ay * s) * radius)
}

/// The angle θ ∈ [0, g] of the circle point `r·(cos θ, sin θ)` that minimises
/// `|p0 − p| + |p1 − p|`: the root of the length's derivative, which is negative at 0 and positive
/// at `g`, by Newton's method kept inside a shrinking bracket (bisection when a step leaves it).
fn shortest_touch(p0: V2, p1: V2, g: f64, r: f64) -> f64 {
    // First and second derivatives of the length in θ.
    let derivatives = |t: f64| -> (f64, f64) {
        let (s, c) = crate::math::sin_cos(t);
        let (p, dp) = (V2::new(c, s) * r, V2::new(-s, c) * r);
        let (mut d1, mut d2) = (0.0, 0.0);
        for e in [p0, p1] {
            let d = p - e;
            let rho = d.norm().max(MINVAL);
            let along = d.dot(&dp);
            d1 += along / rho;
            d2 += (r * r - d.dot(&p)) / rho - along * along / (rho * rho * rho);
        }
        (d1, d2)
    };
    let (mut lo, mut hi) = (0.0, g);
    let mut t = 0.5 * g;
    for _ in 0..100 {
        let (d1, d2) = derivatives(t);
        if d1 == 0.0 {
            return t;
        }
        if d1 < 0.0 {
            lo = t;
        } else {
            hi = t;
        }
        let newton = t - d1 / d2;
        let next = if d2 > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - t).abs() <= 4.0 * f64::EPSILON * t.abs().max(1e-300) || hi - lo <= f64::EPSILON {
            return next;
        }
        t = next;
    }
    t
}

/// Wraps the straight path from `x0` to `x1` (world frame) over a sphere or cylinder of `radius`
/// centred at `center` with orientation `rot`, on the side of the world point `side` if given.
/// `None` when the path stays straight.
pub fn wrap(
    x0: &V3,
    x1: &V3,
    center: &V3,
    rot: &Matrix3<f64>,
    radius: f64,
    shape: WrapShape,
    side: Option<&V3>,
) -> Option<Wrapped> {
    let p0 = rot.tr_mul(&(x0 - center));
    let p1 = rot.tr_mul(&(x1 - center));
    if p0.norm() < MINVAL || p1.norm() < MINVAL {
        return None;
    }
    let axes = match shape {
        WrapShape::Sphere => sphere_plane(&p0, &p1),
        WrapShape::Cylinder => [V3::x(), V3::y()],
    };
    let flat = |p: &V3| V2::new(p.dot(&axes[0]), p.dot(&axes[1]));
    let ends = [flat(&p0), flat(&p1)];
    let local_side = side.map(|s| rot.tr_mul(&(s - center)));
    let (tangents, mut length) = match local_side {
        Some(s) if s.norm() < radius => {
            let t = wrap_inside(ends, radius)?;
            ([t, t], 0.0)
        }
        _ => wrap_circle(ends, local_side.map(|s| unit2(flat(&s)) * radius), radius)?,
    };
    let mut res = tangents.map(|t| axes[0] * t.x + axes[1] * t.y);
    if shape == WrapShape::Cylinder {
        // The helix: heights shared out in proportion to the path's length in the cross-section.
        let l0 = (p0.xy() - res[0].xy()).norm();
        let l1 = (p1.xy() - res[1].xy()).norm();
        let total = l0 + length + l1;
        res[0].z = p0.z + (p1.z - p0.z) * l0 / total;
        res[1].z = p0.z + (p1.z - p0.z) * (l0 + length) / total;
        let height = (res[1].z - res[0].z).abs();
        length = (length * length + height * height).sqrt();
    }
    Some(Wrapped {
        points: res.map(|r| rot * r + center),
        length,
    })
}

/// Two orthonormal axes of the plane through the sphere's centre and both (local) end points:
/// the first towards `p0`. When the ends are in line with the centre, a plane through that line
/// chosen as MuJoCo does (away from the first axis's largest component).
fn sphere_plane(p0: &V3, p1: &V3) -> [V3; 2] {
    let (a0, _) = unit3(*p0);
    let (mut normal, n) = unit3(p0.cross(p1));
    if n < MINVAL {
        let m = a0.map(f64::abs);
        let i = if m.y > m.x && m.y > m.z {
            1
        } else if m.z > m.x && m.z > m.y {
            2
        } else {
            0
        };
        let mut other = V3::repeat(1.0);
        other[i] = 0.0;
        normal = unit3(a0.cross(&other)).0;
    }
    let (a1, _) = unit3(normal.cross(&a0));
    [a0, a1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn a_segment_clear_of_the_circle_does_not_wrap() {
        let ends = [V2::new(-2.0, 2.0), V2::new(2.0, 2.0)];
        assert!(wrap_circle(ends, None, 1.0).is_none());
        // ...unless the side site is on the far side.
        assert!(wrap_circle(ends, Some(V2::new(0.0, -1.0)), 1.0).is_some());
    }

    #[test]
    fn wrap_around_a_unit_circle_closed_form() {
        // Ends at (±2, 0), wrapping over the top (side +y): tangents at (±1/2, √3/2), 60° from
        // each end's direction (cos 60° = r/d), so the arc between them spans π/3.
        let ends = [V2::new(-2.0, 0.0), V2::new(2.0, 0.0)];
        let (t, len) = wrap_circle(ends, Some(V2::new(0.0, 1.0)), 1.0).expect("wraps");
        let h = 3f64.sqrt() / 2.0;
        assert!((t[0] - V2::new(-0.5, h)).norm() < 1e-15, "{t:?}");
        assert!((t[1] - V2::new(0.5, h)).norm() < 1e-15, "{t:?}");
        assert!((len - PI / 3.0).abs() < 1e-14, "{len}");
        // The other side by symmetry.
        let (t, len) = wrap_circle(ends, Some(V2::new(0.0, -1.0)), 1.0).expect("wraps");
        assert!((t[0] - V2::new(-0.5, -h)).norm() < 1e-15, "{t:?}");
        assert!((len - PI / 3.0).abs() < 1e-14, "{len}");
    }

    #[test]
    fn sphere_wrap_length_closed_form() {
        // A sphere of radius 1, ends at distance 2 on opposite sides: two tangents of √3 and a
        // great-circle arc of π/3.
        let w = wrap(
            &V3::new(-2.0, 0.0, 0.0),
            &V3::new(2.0, 0.0, 0.0),
            &V3::zeros(),
            &Matrix3::identity(),
            1.0,
            WrapShape::Sphere,
            Some(&V3::new(0.0, 0.0, 1.5)),
        )
        .expect("wraps");
        let total = (w.points[0] - V3::new(-2.0, 0.0, 0.0)).norm()
            + w.length
            + (V3::new(2.0, 0.0, 0.0) - w.points[1]).norm();
        assert!(
            (total - (2.0 * 3f64.sqrt() + PI / 3.0)).abs() < 1e-14,
            "{total}"
        );
        // The side site above picks the upper half.
        assert!(w.points[0].z > 0.0 && w.points[1].z > 0.0);
    }

    #[test]
    fn cylinder_wrap_adds_the_height_as_a_helix() {
        // Unrolled, the helix and the straight ends make one straight line: the length is
        // √(L_plane² + Δz²) with L_plane the planar wrap's length.
        let (x0, x1) = (V3::new(-2.0, 0.0, -0.3), V3::new(2.0, 0.0, 0.5));
        let w = wrap(
            &x0,
            &x1,
            &V3::zeros(),
            &Matrix3::identity(),
            1.0,
            WrapShape::Cylinder,
            Some(&V3::new(0.0, 2.0, 0.0)),
        )
        .expect("wraps");
        let total = (w.points[0] - x0).norm() + w.length + (x1 - w.points[1]).norm();
        let plane = 2.0 * 3f64.sqrt() + PI / 3.0;
        assert!(
            (total - (plane * plane + 0.8 * 0.8).sqrt()).abs() < 1e-14,
            "{total}"
        );
    }

    #[test]
    fn inside_wrap_touches_the_circle_with_equal_angles() {
        let ends = [V2::new(-1.5, 1.2), V2::new(2.5, 0.8)];
        let t = wrap_inside(ends, 1.0).expect("wraps");
        assert!((t.norm() - 1.0).abs() < 1e-12);
        // The path's two pieces make equal angles with the surface normal at the contact point.
        let n = t.normalize();
        let (u0, u1) = ((ends[0] - t).normalize(), (ends[1] - t).normalize());
        assert!(
            (u0.dot(&n) - u1.dot(&n)).abs() < 1e-5,
            "{} {}",
            u0.dot(&n),
            u1.dot(&n)
        );
    }

    #[test]
    fn degenerate_inputs_give_no_wrap_and_no_nan() {
        let ends = [V2::new(0.0, 0.0), V2::new(2.0, 0.0)];
        assert!(wrap_circle(ends, None, 1.0).is_none());
        assert!(wrap_inside(ends, 1.0).is_none());
        let same = [V2::new(2.0, 0.0), V2::new(2.0, 0.0)];
        assert!(wrap_circle(same, None, 1.0).is_none());
        let w = wrap(
            &V3::zeros(),
            &V3::new(1.0, 0.0, 0.0),
            &V3::zeros(),
            &Matrix3::identity(),
            0.5,
            WrapShape::Sphere,
            None,
        );
        assert!(w.is_none());
    }
}
