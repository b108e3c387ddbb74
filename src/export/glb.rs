//! An animated glTF 2.0 binary (`.glb`) of a recording: the simulated and the reference
//! skeletons as node hierarchies (one node per body, a child node per geom with its mesh), one
//! animation per episode with a keyframe per control step (the root's translation, every body's
//! rotation; other bodies keep their fixed offsets). A top node turns MuJoCo's Z-up into
//! glTF's Y-up. The reference is translucent (alpha blending), the simulated character opaque.

use std::collections::BTreeMap;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use json::{Index, Root};
use nalgebra::UnitQuaternion;

use crate::motion::Character;
use crate::recording::{Outcome, Recording, Track};

use super::mesh::TriMesh;
use super::skeleton::{Skeleton, continuous};
use super::{ExportError, Format, z_up_to_y_up};

/// RGBA of the two characters (the page's colours).
const SIMULATED_COLOR: [f32; 4] = [0.85, 0.45, 0.18, 1.0];
const REFERENCE_COLOR: [f32; 4] = [0.23, 0.49, 0.85, 0.35];

/// The binary chunk, each piece aligned to 4 bytes (glTF's rule for float data).
#[derive(Default)]
struct Binary {
    bytes: Vec<u8>,
}

impl Binary {
    fn append(&mut self, data: impl IntoIterator<Item = u8>) -> (usize, usize) {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let start = self.bytes.len();
        self.bytes.extend(data);
        (start, self.bytes.len() - start)
    }
}

/// A glTF document under construction.
struct Builder {
    root: Root,
    bin: Binary,
}

impl Builder {
    /// A buffer view of `data` and an accessor over all of it.
    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        data: Vec<u8>,
        count: usize,
        component: json::accessor::ComponentType,
        kind: json::accessor::Type,
        target: Option<json::buffer::Target>,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
        name: &str,
    ) -> Index<json::Accessor> {
        let (offset, length) = self.bin.append(data);
        let view = self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64::from(length),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        });
        let (min, max) = match bounds {
            Some((lo, hi)) => (Some(json::Value::from(lo)), Some(json::Value::from(hi))),
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: Some(USize64(0)),
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(kind),
            min,
            max,
            name: Some(name.to_string()),
            normalized: false,
            sparse: None,
        })
    }

    fn floats(
        &mut self,
        values: &[f32],
        kind: json::accessor::Type,
        target: Option<json::buffer::Target>,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
        name: &str,
    ) -> Index<json::Accessor> {
        let width = kind.multiplicity();
        let data = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(
            data,
            values.len() / width,
            json::accessor::ComponentType::F32,
            kind,
            target,
            bounds,
            name,
        )
    }

    fn material(&mut self, name: &str, color: [f32; 4]) -> Index<json::Material> {
        let mut material = json::Material {
            name: Some(name.to_string()),
            ..Default::default()
        };
        material.pbr_metallic_roughness.base_color_factor =
            json::material::PbrBaseColorFactor(color);
        material.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
        material.pbr_metallic_roughness.roughness_factor = json::material::StrengthFactor(0.6);
        if color[3] < 1.0 {
            material.alpha_mode = Valid(json::material::AlphaMode::Blend);
        }
        self.root.push(material)
    }

    fn node(&mut self, node: json::Node) -> Index<json::Node> {
        self.root.push(node)
    }
}

/// Geometry accessors of one geom (shared by both skeletons' meshes).
struct GeomGeometry {
    body: usize,
    positions: Index<json::Accessor>,
    normals: Index<json::Accessor>,
    indices: Index<json::Accessor>,
    translation: [f32; 3],
    rotation: [f32; 4],
}

fn quat_xyzw(q: &UnitQuaternion<f64>) -> [f32; 4] {
    let q = q.quaternion();
    [q.i as f32, q.j as f32, q.k as f32, q.w as f32]
}

/// Nodes of one skeleton under a root node named `name`; returns the root node and each
/// body's node.
fn skeleton_nodes(
    builder: &mut Builder,
    skeleton: &Skeleton,
    geoms: &[GeomGeometry],
    material: Index<json::Material>,
    name: &str,
) -> (Index<json::Node>, Vec<Index<json::Node>>) {
    let mut children: BTreeMap<usize, Vec<Index<json::Node>>> = BTreeMap::new();
    for (g, geom) in geoms.iter().enumerate() {
        let mesh = builder.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(format!("{name}/{}/geom{g}", skeleton.names[geom.body])),
            primitives: vec![json::mesh::Primitive {
                attributes: BTreeMap::from([
                    (Valid(json::mesh::Semantic::Positions), geom.positions),
                    (Valid(json::mesh::Semantic::Normals), geom.normals),
                ]),
                extensions: None,
                extras: Default::default(),
                indices: Some(geom.indices),
                material: Some(material),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        });
        let node = builder.node(json::Node {
            mesh: Some(mesh),
            name: Some(format!("{name}/{}/geom{g}", skeleton.names[geom.body])),
            translation: Some(geom.translation),
            rotation: Some(json::scene::UnitQuaternion(geom.rotation)),
            ..Default::default()
        });
        children.entry(geom.body).or_default().push(node);
    }
    // Children before parents, so that each body node is made with its children's indices.
    let mut nodes: Vec<Option<Index<json::Node>>> = vec![None; skeleton.len()];
    for b in (0..skeleton.len()).rev() {
        let mut kids = children.remove(&b).unwrap_or_default();
        kids.extend(
            (b + 1..skeleton.len())
                .filter(|&c| skeleton.parents[c] == Some(b))
                .filter_map(|c| nodes[c]),
        );
        let offset = skeleton.offsets[b];
        nodes[b] = Some(builder.node(json::Node {
            name: Some(format!("{name}/{}", skeleton.names[b])),
            translation: Some([offset.x as f32, offset.y as f32, offset.z as f32]),
            children: (!kids.is_empty()).then_some(kids),
            ..Default::default()
        }));
    }
    let nodes: Vec<Index<json::Node>> = nodes.into_iter().flatten().collect();
    let roots: Vec<Index<json::Node>> = (0..skeleton.len())
        .filter(|&b| skeleton.parents[b].is_none())
        .map(|b| nodes[b])
        .collect();
    let top = builder.node(json::Node {
        name: Some(name.to_string()),
        children: Some(roots),
        ..Default::default()
    });
    (top, nodes)
}

/// One character in the document: its track, its top node and its body nodes.
struct SkeletonNodes<'a> {
    track: &'a Track,
    top: Index<json::Node>,
    bodies: Vec<Index<json::Node>>,
    name: &'static str,
}

/// One episode's channels for one skeleton: the root's translation, every body's rotation.
fn animate(
    builder: &mut Builder,
    animation: &mut json::Animation,
    times: Index<json::Accessor>,
    skeleton: &Skeleton,
    nodes: &SkeletonNodes<'_>,
    rows: std::ops::Range<usize>,
) {
    let (track, name) = (nodes.track, nodes.name);
    let mut channel = |builder: &mut Builder, node, path, values: Vec<f32>, kind| {
        let output = builder.floats(&values, kind, None, None, name);
        let sampler = Index::new(animation.samplers.len() as u32);
        animation.samplers.push(json::animation::Sampler {
            extensions: None,
            extras: Default::default(),
            input: times,
            interpolation: Valid(json::animation::Interpolation::Linear),
            output,
        });
        animation.channels.push(json::animation::Channel {
            sampler,
            target: json::animation::Target {
                extensions: None,
                extras: Default::default(),
                node,
                path: Valid(path),
            },
            extensions: None,
            extras: Default::default(),
        });
    };
    for (b, &node) in nodes.bodies.iter().enumerate() {
        if skeleton.parents[b].is_none() {
            let positions = rows
                .clone()
                .flat_map(|row| {
                    let p = track.position(row, b);
                    [p.x as f32, p.y as f32, p.z as f32]
                })
                .collect();
            channel(
                builder,
                node,
                json::animation::Property::Translation,
                positions,
                json::accessor::Type::Vec3,
            );
        }
        let mut previous: Option<UnitQuaternion<f64>> = None;
        let mut rotations = Vec::with_capacity(4 * rows.len());
        for row in rows.clone() {
            let q = continuous(skeleton.local_rotations(track, row)[b], previous.as_ref());
            rotations.extend(quat_xyzw(&q));
            previous = Some(q);
        }
        channel(
            builder,
            node,
            json::animation::Property::Rotation,
            rotations,
            json::accessor::Type::Vec4,
        );
    }
}

fn episode_name(recording: &Recording, e: usize) -> String {
    let info = &recording.episodes()[e];
    match info.outcome {
        Outcome::Reference => format!("{} (reference clip)", recording.meta.motion),
        Outcome::Failed => format!(
            "episode {e} (failed at frame {})",
            info.failed_frame.map_or("?".to_string(), |f| f.to_string())
        ),
        other => format!("episode {e} ({other:?})").to_lowercase(),
    }
}

/// The `.glb` bytes of `recording` for `character`.
pub fn glb_bytes(recording: &Recording, character: &Character) -> Result<Vec<u8>, ExportError> {
    let encode = |problem: String| ExportError::Encode {
        format: Format::Glb,
        problem,
    };
    let skeleton = Skeleton::of(character)?;
    let mut builder = Builder {
        root: Root {
            asset: json::Asset {
                generator: Some(format!("instantmimic {}", env!("CARGO_PKG_VERSION"))),
                ..Default::default()
            },
            ..Default::default()
        },
        bin: Binary::default(),
    };
    builder.root.push(json::Buffer {
        byte_length: USize64(0),
        extensions: None,
        extras: Default::default(),
        name: None,
        uri: None,
    });
    let mut geoms = Vec::new();
    for geom in character.geoms().iter().filter(|g| g.body > 0) {
        let Some(mesh) = TriMesh::of(&geom.shape) else {
            continue;
        };
        let (lo, hi) = mesh.bounds();
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let positions = builder.floats(
            &flat(&mesh.positions),
            json::accessor::Type::Vec3,
            Some(json::buffer::Target::ArrayBuffer),
            Some((lo.to_vec(), hi.to_vec())),
            &geom.name,
        );
        let normals = builder.floats(
            &flat(&mesh.normals),
            json::accessor::Type::Vec3,
            Some(json::buffer::Target::ArrayBuffer),
            None,
            &geom.name,
        );
        let indices = builder.accessor(
            mesh.indices.iter().flat_map(|i| i.to_le_bytes()).collect(),
            mesh.indices.len(),
            json::accessor::ComponentType::U16,
            json::accessor::Type::Scalar,
            Some(json::buffer::Target::ElementArrayBuffer),
            None,
            &geom.name,
        );
        geoms.push(GeomGeometry {
            body: geom.body - 1,
            positions,
            normals,
            indices,
            translation: [geom.pos.x as f32, geom.pos.y as f32, geom.pos.z as f32],
            rotation: quat_xyzw(&geom.quat),
        });
    }

    let mut skeletons: Vec<SkeletonNodes<'_>> = Vec::new();
    if let Some(simulated) = recording.simulated() {
        let material = builder.material("simulated", SIMULATED_COLOR);
        let (top, bodies) = skeleton_nodes(&mut builder, &skeleton, &geoms, material, "simulated");
        skeletons.push(SkeletonNodes {
            track: simulated,
            top,
            bodies,
            name: "simulated",
        });
    }
    // The reference is the solid character when it is alone.
    let color = if recording.simulated().is_some() {
        REFERENCE_COLOR
    } else {
        [
            REFERENCE_COLOR[0],
            REFERENCE_COLOR[1],
            REFERENCE_COLOR[2],
            1.0,
        ]
    };
    let material = builder.material("reference", color);
    let (top, bodies) = skeleton_nodes(&mut builder, &skeleton, &geoms, material, "reference");
    skeletons.push(SkeletonNodes {
        track: recording.reference(),
        top,
        bodies,
        name: "reference",
    });

    let y_up = builder.node(json::Node {
        name: Some("instantmimic (Z-up to Y-up)".to_string()),
        rotation: Some(json::scene::UnitQuaternion(quat_xyzw(&z_up_to_y_up()))),
        children: Some(skeletons.iter().map(|s| s.top).collect()),
        ..Default::default()
    });
    let scene = builder.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some(recording.meta.motion.clone()),
        nodes: vec![y_up],
    });
    builder.root.scene = Some(scene);

    let dt = recording.meta.control_dt;
    for e in 0..recording.episodes().len() {
        let rows = recording.episode_rows(e)?;
        let times: Vec<f32> = (0..rows.len()).map(|f| (f as f64 * dt) as f32).collect();
        let last = times.last().copied().unwrap_or(0.0);
        let times = builder.floats(
            &times,
            json::accessor::Type::Scalar,
            None,
            Some((vec![0.0], vec![last])),
            "time",
        );
        let mut animation = json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: Vec::new(),
            name: Some(episode_name(recording, e)),
            samplers: Vec::new(),
        };
        for nodes in &skeletons {
            animate(
                &mut builder,
                &mut animation,
                times,
                &skeleton,
                nodes,
                rows.clone(),
            );
        }
        builder.root.push(animation);
    }

    let Builder { mut root, mut bin } = builder;
    bin.append([]);
    root.buffers[0].byte_length = USize64::from(bin.bytes.len());
    let text = json::serialize::to_string(&root).map_err(|e| encode(e.to_string()))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            // Filled in by `to_vec`.
            length: 0,
        },
        json: std::borrow::Cow::Owned(text.into_bytes()),
        bin: Some(std::borrow::Cow::Owned(bin.bytes)),
    };
    glb.to_vec().map_err(|e| encode(e.to_string()))
}
