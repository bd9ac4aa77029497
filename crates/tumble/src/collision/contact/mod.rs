//! TEMP stand-in
use crate::collision::manifold::{ContactPoint, Manifold};
use crate::math::{Transform, Vec3};
use crate::shape::Shape;
pub fn collide(
    a: &Shape,
    pa: &Transform,
    b: &Shape,
    pb: &Transform,
    margin: f32,
    out: &mut Manifold,
) {
    out.clear();
    match (a, b) {
        (Shape::Plane(_), Shape::Plane(_)) => {}
        (Shape::Plane(_), _) => {
            collide(b, pb, a, pa, margin, out);
            *out = out.flipped();
        }
        (_, Shape::Plane(p)) => {
            let n = pb.rotation * p.normal;
            let level = p.offset + n.dot(pb.position);
            out.normal = n;
            match a {
                Shape::Sphere(s) => {
                    let d = n.dot(pa.position) - level - s.radius;
                    if d < margin {
                        out.push(ContactPoint {
                            position: pa.position - n * (s.radius + 0.5 * d),
                            separation: d,
                            id: 0,
                        })
                    }
                }
                Shape::Cuboid(c) => {
                    for i in 0..8u32 {
                        let v = pa.transform_point(
                            Vec3::new(
                                if i & 1 == 0 { -1.0 } else { 1.0 },
                                if i & 2 == 0 { -1.0 } else { 1.0 },
                                if i & 4 == 0 { -1.0 } else { 1.0 },
                            ) * c.half_extents,
                        );
                        let d = n.dot(v) - level;
                        if d < margin && out.count < 4 {
                            out.push(ContactPoint {
                                position: v - n * (0.5 * d),
                                separation: d,
                                id: i,
                            })
                        }
                    }
                }
                _ => {}
            }
        }
        (Shape::Sphere(sa), Shape::Sphere(sb)) => {
            let d = pa.position - pb.position;
            let len = d.length();
            let n = if len > 0.0 { d / len } else { Vec3::Y };
            let s = len - sa.radius - sb.radius;
            if s < margin {
                out.normal = n;
                out.push(ContactPoint {
                    position: pb.position + n * (sb.radius + 0.5 * s),
                    separation: s,
                    id: 0,
                })
            }
        }
        _ => {}
    }
}
