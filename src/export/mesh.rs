//! Triangle meshes of the MJCF's geom shapes, in the geom's frame (capsules and cylinders along
//! +z, MuJoCo's half sizes), with outward normals and counter-clockwise faces, for glTF.

use std::f64::consts::PI;

use crate::motion::character::GeomShape;

/// Positions, normals and triangle indices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub indices: Vec<u16>,
}

/// Latitude rings (pole to pole) and longitude segments of round shapes: enough to look round
/// in a viewer, few enough to keep a file small (~200 vertices a geom).
const RINGS: usize = 12;
const SEGMENTS: usize = 16;

impl TriMesh {
    /// The mesh of `shape`; `None` for a plane (infinite: the floor, not exported).
    pub fn of(shape: &GeomShape) -> Option<TriMesh> {
        Some(match *shape {
            GeomShape::Plane => return None,
            GeomShape::Sphere { radius } => round([radius; 3], 0.0),
            GeomShape::Capsule {
                radius,
                half_length,
            } => round([radius; 3], half_length),
            GeomShape::Ellipsoid { radii } => round([radii.x, radii.y, radii.z], 0.0),
            GeomShape::Cylinder {
                radius,
                half_length,
            } => cylinder(radius, half_length),
            GeomShape::Box { half_extents } => {
                cuboid([half_extents.x, half_extents.y, half_extents.z])
            }
        })
    }

    /// The smallest and largest coordinates (glTF wants them for positions).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        (lo, hi)
    }

    fn push(&mut self, position: [f64; 3], normal: [f64; 3]) -> u16 {
        let n = (normal[0].powi(2) + normal[1].powi(2) + normal[2].powi(2)).sqrt();
        self.positions.push(position.map(|v| v as f32));
        self.normals.push(normal.map(|v| (v / n) as f32));
        (self.positions.len() - 1) as u16
    }
}

/// A sphere scaled by `radii` (an ellipsoid), its halves moved apart by `half` along z (a
/// capsule: the equator is doubled and the gap is the cylinder).
fn round(radii: [f64; 3], half: f64) -> TriMesh {
    let mut mesh = TriMesh::default();
    // Ring latitudes with the z shift of their half; the equator twice for a capsule.
    let mut rings: Vec<(f64, f64)> = Vec::new();
    for i in 0..=RINGS {
        let theta = PI * i as f64 / RINGS as f64;
        if half > 0.0 && 2 * i == RINGS {
            rings.push((theta, half));
            rings.push((theta, -half));
        } else {
            rings.push((theta, if 2 * i < RINGS { half } else { -half }));
        }
    }
    for &(theta, shift) in &rings {
        for j in 0..=SEGMENTS {
            let phi = 2.0 * PI * j as f64 / SEGMENTS as f64;
            let n = [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ];
            let p = [radii[0] * n[0], radii[1] * n[1], radii[2] * n[2] + shift];
            // An ellipsoid's normal is the sphere's divided by the radii.
            mesh.push(p, [n[0] / radii[0], n[1] / radii[1], n[2] / radii[2]]);
        }
    }
    let stride = SEGMENTS + 1;
    for i in 0..rings.len() - 1 {
        for j in 0..SEGMENTS {
            let a = (i * stride + j) as u16;
            let b = a + stride as u16;
            // Quads touching a pole are triangles: leave out the one with two pole corners.
            if i > 0 {
                mesh.indices.extend([a, b, a + 1]);
            }
            if i + 2 < rings.len() {
                mesh.indices.extend([a + 1, b, b + 1]);
            }
        }
    }
    mesh
}

fn cylinder(radius: f64, half: f64) -> TriMesh {
    let mut mesh = TriMesh::default();
    let ring = |mesh: &mut TriMesh, z: f64, normal_z: f64| -> Vec<u16> {
        (0..=SEGMENTS)
            .map(|j| {
                let phi = 2.0 * PI * j as f64 / SEGMENTS as f64;
                let (c, s) = (phi.cos(), phi.sin());
                let normal = if normal_z == 0.0 {
                    [c, s, 0.0]
                } else {
                    [0.0, 0.0, normal_z]
                };
                mesh.push([radius * c, radius * s, z], normal)
            })
            .collect()
    };
    let (top, bottom) = (ring(&mut mesh, half, 0.0), ring(&mut mesh, -half, 0.0));
    for j in 0..SEGMENTS {
        mesh.indices.extend([top[j], bottom[j], top[j + 1]]);
        mesh.indices.extend([top[j + 1], bottom[j], bottom[j + 1]]);
    }
    for (z, sign) in [(half, 1.0), (-half, -1.0)] {
        let center = mesh.push([0.0, 0.0, z], [0.0, 0.0, sign]);
        let rim = ring(&mut mesh, z, sign);
        for j in 0..SEGMENTS {
            if sign > 0.0 {
                mesh.indices.extend([center, rim[j], rim[j + 1]]);
            } else {
                mesh.indices.extend([center, rim[j + 1], rim[j]]);
            }
        }
    }
    mesh
}

fn cuboid(half: [f64; 3]) -> TriMesh {
    let mut mesh = TriMesh::default();
    // Each face: its normal axis and sign; corners walk counter-clockwise seen from outside.
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut normal = [0.0; 3];
            normal[axis] = sign;
            let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
            let ids: Vec<u16> = corners
                .iter()
                .map(|&(a, b)| {
                    let mut p = [0.0; 3];
                    p[axis] = sign * half[axis];
                    p[u] = a * half[u];
                    p[v] = sign * b * half[v];
                    mesh.push(p, normal)
                })
                .collect();
            mesh.indices
                .extend([ids[0], ids[1], ids[2], ids[0], ids[2], ids[3]]);
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// Every face's winding agrees with its vertices' normals (counter-clockwise from outside)
    /// and no face is degenerate.
    fn check_faces(mesh: &TriMesh) {
        let v = |i: u16| {
            let p = mesh.positions[i as usize];
            Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
        };
        for tri in mesh.indices.chunks_exact(3) {
            let face = (v(tri[1]) - v(tri[0])).cross(&(v(tri[2]) - v(tri[0])));
            assert!(face.norm() > 1e-9, "degenerate face {tri:?}");
            let n = mesh.normals[tri[0] as usize];
            let normal = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
            assert!(face.dot(&normal) > 0.0, "face {tri:?} winds inward");
        }
    }

    #[test]
    fn shapes_are_closed_outward_meshes_of_the_right_size() {
        let capsule = TriMesh::of(&GeomShape::Capsule {
            radius: 0.05,
            half_length: 0.15,
        })
        .expect("mesh");
        let (lo, hi) = capsule.bounds();
        assert!(
            (hi[2] - 0.2).abs() < 1e-6 && (lo[2] + 0.2).abs() < 1e-6,
            "{lo:?} {hi:?}"
        );
        assert!((hi[0] - 0.05).abs() < 1e-6);
        let boxed = TriMesh::of(&GeomShape::Box {
            half_extents: Vector3::new(0.1, 0.2, 0.3),
        })
        .expect("mesh");
        assert_eq!(boxed.bounds(), ([-0.1, -0.2, -0.3], [0.1, 0.2, 0.3]));
        for mesh in [
            capsule,
            boxed,
            TriMesh::of(&GeomShape::Sphere { radius: 0.1 }).expect("mesh"),
            TriMesh::of(&GeomShape::Cylinder {
                radius: 0.1,
                half_length: 0.2,
            })
            .expect("mesh"),
        ] {
            check_faces(&mesh);
        }
        assert!(TriMesh::of(&GeomShape::Plane).is_none());
    }
}
