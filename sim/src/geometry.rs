//! Collision geometry of the ball world: signed distances from the ball's centre to boxes, planes and
//! cylinders, with the outward normal and which feature (face, edge, side) is nearest.
//!
//! Pure functions of positions; no state, no allocation. Distances are to the shape's surface;
//! subtract the ball radius to get the gap between surfaces.

use nalgebra::{UnitQuaternion, Vector3};

use crate::arena;
use crate::model::{GeomKind, Model};

type V3 = Vector3<f64>;

/// Which part of a shape the nearest surface point lies on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Feature {
    /// A box's top face, or a cylinder's flat face (the blade's hitting surface).
    Top,
    /// The border between the top (or flat) face and a side: the table's edge, the blade's rim edge.
    Edge,
    /// A box's side or bottom face, or a cylinder's curved side.
    Side,
}

/// The nearest surface point of a shape to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proximity {
    /// Signed distance from the query point to the surface (negative inside), m.
    pub distance: f64,
    /// Unit outward normal at the nearest point (the direction that increases the distance).
    pub normal: V3,
    /// The nearest point on the surface.
    pub point: V3,
    /// Which feature that point lies on.
    pub feature: Feature,
}

/// An axis-aligned box, as the table and the net are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Centre, m.
    pub center: V3,
    /// Half-sizes, m.
    pub half: V3,
}

impl Aabb {
    /// The table as one solid box from below the floor to the playing surface (docs/design.md §4).
    pub fn table() -> Aabb {
        Aabb {
            center: V3::new(0.0, arena::TABLE_CENTER_Y, 0.0),
            half: V3::new(
                arena::TABLE_HALF_LENGTH,
                arena::TABLE_HALF_WIDTH,
                arena::TABLE_TOP_Z,
            ),
        }
    }

    /// The net box (docs/design.md §4).
    pub fn net() -> Aabb {
        Aabb {
            center: V3::from(arena::NET_CENTER),
            half: V3::from(arena::NET_HALF_SIZE),
        }
    }

    /// Nearest surface point to `p`. The top face is +z; an edge is where the top face meets a
    /// side face (the point is on the top face's border).
    pub fn proximity(&self, p: &V3) -> Proximity {
        let d = p - self.center;
        let q = d.abs() - self.half;
        if q.x <= 0.0 && q.y <= 0.0 && q.z <= 0.0 {
            // Inside: the nearest face is the one of least penetration.
            let (axis, depth) =
                [q.x, q.y, q.z]
                    .iter()
                    .enumerate()
                    .fold((0, f64::NEG_INFINITY), |best, (i, &v)| {
                        if v > best.1 {
                            (i, v)
                        } else {
                            best
                        }
                    });
            let mut normal = V3::zeros();
            normal[axis] = if d[axis] >= 0.0 { 1.0 } else { -1.0 };
            let mut point = *p;
            point[axis] = self.center[axis] + normal[axis] * self.half[axis];
            let feature = if axis == 2 && normal.z > 0.0 {
                Feature::Top
            } else {
                Feature::Side
            };
            return Proximity {
                distance: depth,
                normal,
                point,
                feature,
            };
        }
        let clamped = V3::new(
            d.x.clamp(-self.half.x, self.half.x),
            d.y.clamp(-self.half.y, self.half.y),
            d.z.clamp(-self.half.z, self.half.z),
        );
        let point = self.center + clamped;
        let diff = d - clamped;
        let distance = diff.norm();
        let normal = diff / distance;
        let on_top = clamped.z >= self.half.z;
        let on_border = clamped.x.abs() >= self.half.x || clamped.y.abs() >= self.half.y;
        let feature = match (on_top, on_border && diff.z.abs() < distance) {
            (true, false) => Feature::Top,
            (true, true) => Feature::Edge,
            (false, _) => Feature::Side,
        };
        Proximity {
            distance,
            normal,
            point,
            feature,
        }
    }
}

/// A horizontal plane `z = height` with +z outward (the floor).
pub fn plane_proximity(height: f64, p: &V3) -> Proximity {
    Proximity {
        distance: p.z - height,
        normal: V3::z(),
        point: V3::new(p.x, p.y, height),
        feature: Feature::Top,
    }
}

/// A solid cylinder in its own frame: axis along local `axis` (0 = x, 2 = z), centred at `center`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    /// Centre in the owning body's frame, m.
    pub center: V3,
    /// Index of the local axis the cylinder runs along: 0 (x) or 2 (z).
    pub axis: usize,
    /// Radius, m.
    pub radius: f64,
    /// Half-length along the axis, m.
    pub half_length: f64,
}

impl Cylinder {
    /// Nearest surface point to `p`, all in the owning body's frame. `Top` is a flat face, `Edge` its
    /// rim, `Side` the curved surface.
    pub fn proximity(&self, p: &V3) -> Proximity {
        let d = p - self.center;
        let along = d[self.axis];
        let mut radial = d;
        radial[self.axis] = 0.0;
        let rho = radial.norm();
        let axis_dir = {
            let mut a = V3::zeros();
            a[self.axis] = if along >= 0.0 { 1.0 } else { -1.0 };
            a
        };
        // A point on the axis has no radial direction: pick any perpendicular one.
        let radial_dir = if rho > 1e-12 {
            radial / rho
        } else {
            let mut r = V3::zeros();
            r[(self.axis + 1) % 3] = 1.0;
            r
        };
        let dr = rho - self.radius;
        let da = along.abs() - self.half_length;
        if dr > 0.0 && da > 0.0 {
            // Beyond the rim: nearest point is on the circular edge.
            let point_local = radial_dir * self.radius + axis_dir * self.half_length;
            let diff = d - point_local;
            let distance = diff.norm();
            return Proximity {
                distance,
                normal: diff / distance,
                point: self.center + point_local,
                feature: Feature::Edge,
            };
        }
        if da >= dr {
            // Nearest the flat face (outside it, or inside the solid closer to it).
            // Here dr ≤ 0: the point is within the radius, so it projects straight onto the face.
            let point_local = radial + axis_dir * self.half_length;
            Proximity {
                distance: da,
                normal: axis_dir,
                point: self.center + point_local,
                feature: Feature::Top,
            }
        } else {
            let point_local =
                radial_dir * self.radius + axis_dir * along.abs().min(self.half_length);
            Proximity {
                distance: dr,
                normal: radial_dir,
                point: self.center + point_local,
                feature: Feature::Side,
            }
        }
    }

    /// Radius of a sphere about the body origin that holds the whole cylinder, m.
    pub fn bounding_radius(&self) -> f64 {
        self.center.norm()
            + (self.radius * self.radius + self.half_length * self.half_length).sqrt()
    }
}

/// The paddle's collision shape in its own frame: blade and handle (docs/design.md §4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaddleShape {
    /// The blade; its axis (normal) is the paddle frame's z.
    pub blade: Cylinder,
    /// The handle; its axis is the paddle frame's x.
    pub handle: Cylinder,
}

impl PaddleShape {
    /// The paddle of `model`'s body `paddle`: its cylinder geoms named `blade` (axis along the
    /// paddle frame's z: the blade's normal) and `handle` (along x). Fails, naming what is missing
    /// or wrong, if the model does not describe such a paddle.
    pub fn from_model(model: &Model, paddle: usize) -> Result<PaddleShape, String> {
        let body = &model.bodies[paddle].name;
        let cylinder = |name: &str, axis: usize| -> Result<Cylinder, String> {
            let g = model
                .geoms
                .iter()
                .find(|g| g.body == paddle && g.name == name)
                .ok_or_else(|| format!("body '{body}' has no geom named '{name}'"))?;
            if g.kind != GeomKind::Cylinder {
                return Err(format!("geom '{name}' of body '{body}' must be a cylinder"));
            }
            // Within 1e-6 of the axis (about 0.08°): MyoSuite's handle is tilted by 0.05°, which
            // moves its ends by 4e-5 m; the shape is taken as aligned.
            let along = g.quat * V3::z();
            if (along[axis].abs() - 1.0).abs() > 1e-6 {
                return Err(format!(
                    "geom '{name}' of body '{body}': its axis must lie along the paddle frame's {}",
                    ["x", "y", "z"][axis]
                ));
            }
            Ok(Cylinder {
                center: g.pos,
                axis,
                radius: g.size[0],
                half_length: g.size[1],
            })
        };
        Ok(PaddleShape {
            blade: cylinder("blade", 2)?,
            handle: cylinder("handle", 0)?,
        })
    }

    /// The default robot's paddle (`config/models/upper_body.xml`: MyoSuite's, a 0.093 m blade
    /// 4 cm thick and a 0.016 m handle), for scenes without a robot.
    pub fn standard() -> PaddleShape {
        static SHAPE: std::sync::OnceLock<PaddleShape> = std::sync::OnceLock::new();
        *SHAPE.get_or_init(|| {
            let model = crate::config::default_model();
            let paddle = model
                .body("paddle")
                .expect("the default model has a paddle");
            PaddleShape::from_model(&model, paddle).expect("the default model's paddle is valid")
        })
    }

    /// This paddle with another blade thickness (e.g. a realistic 5 mm blade: 0.0025).
    pub fn with_blade_half_thickness(mut self, half_thickness: f64) -> PaddleShape {
        self.blade.half_length = half_thickness;
        self
    }

    /// Nearest surface point of blade or handle to `p`, in the paddle frame.
    pub fn proximity(&self, p: &V3) -> Proximity {
        let b = self.blade.proximity(p);
        let h = self.handle.proximity(p);
        if h.distance < b.distance {
            h
        } else {
            b
        }
    }

    /// Radius of a sphere about the paddle origin that holds blade and handle, m.
    pub fn bounding_radius(&self) -> f64 {
        self.blade
            .bounding_radius()
            .max(self.handle.bounding_radius())
    }
}

/// Where a rigid body is and how it moves, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position of the body origin, m.
    pub pos: V3,
    /// Orientation (body → world).
    pub rot: UnitQuaternion<f64>,
}

impl Pose {
    /// A world point expressed in the body frame.
    pub fn to_local(&self, p: &V3) -> V3 {
        self.rot.inverse_transform_vector(&(p - self.pos))
    }

    /// A body-frame point in the world frame.
    pub fn to_world(&self, p: &V3) -> V3 {
        self.pos + self.rot * p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_top_edge_and_side_are_told_apart() {
        let t = Aabb::table();
        let top = t.proximity(&V3::new(0.5, 0.0, 0.9));
        assert_eq!(top.feature, Feature::Top);
        assert!((top.distance - (0.9 - arena::TABLE_TOP_Z)).abs() < 1e-12);
        assert_eq!(top.normal, V3::z());
        // Beyond the end line and above the top: nearest the edge.
        let edge = t.proximity(&V3::new(1.38, 0.0, 0.80));
        assert_eq!(edge.feature, Feature::Edge);
        // Beyond the end line and below the top: the side face.
        let side = t.proximity(&V3::new(1.38, 0.0, 0.70));
        assert_eq!(side.feature, Feature::Side);
        assert!((side.distance - 0.01).abs() < 1e-12);
        assert_eq!(side.normal, V3::x());
    }

    #[test]
    fn cylinder_distances_match_closed_forms() {
        let c = Cylinder {
            center: V3::zeros(),
            axis: 2,
            radius: 0.1,
            half_length: 0.01,
        };
        let face = c.proximity(&V3::new(0.05, 0.0, 0.03));
        assert_eq!(face.feature, Feature::Top);
        assert!((face.distance - 0.02).abs() < 1e-12);
        let side = c.proximity(&V3::new(0.13, 0.0, 0.0));
        assert_eq!(side.feature, Feature::Side);
        assert!((side.distance - 0.03).abs() < 1e-12);
        let rim = c.proximity(&V3::new(0.13, 0.0, 0.05));
        assert_eq!(rim.feature, Feature::Edge);
        assert!((rim.distance - 0.05).abs() < 1e-12);
        let inside = c.proximity(&V3::new(0.0, 0.0, -0.004));
        assert!((inside.distance + 0.006).abs() < 1e-12);
        assert_eq!(inside.normal, -V3::z());
    }
}
