//! Task props: the table scene (docs/tasks.md §0.1) and builders for the objects the tasks use.
//!
//! Dynamic props are free bodies with density [`DENSITY`] (mass from volume, as SAPIEN's
//! `add_*_collision(density=1000)`); kinematic props are MuJoCo mocap bodies (moved by
//! writing `mocap_pos`/`mocap_quat`); visual-only markers have no collision.
use std::f64::consts::FRAC_1_SQRT_2;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::xml::{nums, Element};
use super::{
    pose_attrs, Scene, CONTACT_GROUND, CONTACT_TABLE_BOX, CONTACT_TABLE_PLANE, DENSITY, GROUND,
    GROUP_HIDDEN, TABLE, TORSIONAL_ROLLING,
};

/// Half extents of the table-workspace box in its actor frame (docs/tasks.md §0.1).
pub const TABLE_HALF: [f64; 3] = [1.209, 0.6045, 0.45982145];
/// Table actor position (its box centre is `TABLE_HALF[2]` above it).
pub const TABLE_POS: [f64; 3] = [-0.12, 0.0, -0.9196429];
/// Name of the table-top plane geom that props rest on.
pub const TABLE_TOP_PLANE: &str = "table-top";
/// Height of the ground plane (= −table height).
pub const GROUND_Z: f64 = -0.91964293;
/// Drawn size of the ground plane (half extents and grid spacing; it collides as an
/// infinite plane).
pub const GROUND_DRAWN_SIZE: [f64; 3] = [50.0, 50.0, 5.0];

/// RGBA colour.
pub type Rgba = [f64; 4];
/// Plain white.
pub const WHITE: Rgba = [1.0, 1.0, 1.0, 1.0];

/// The table model (converted from ManiSkill's `table.glb` at scale 1.75; docs/rendering.md),
/// relative to `models/`.
pub const TABLE_MODEL: &str = "scene/table.urdf";
/// The floor's grid texture, relative to `models/`.
pub const GROUND_TEXTURE: &str = "scene/grid.png";
/// Colour the floor texture is multiplied by.
pub const GROUND_RGBA: Rgba = [1.0, 1.0, 1.0, 1.0];
/// Ambient light (the first directional light's ambient term). ManiSkill's ambient is 0.3 in linear light,
/// ≈ 0.55 after its sRGB output encoding; MuJoCo's fixed-function lighting works on display
/// values, so the intensities were fitted to ManiSkill's frames (docs/rendering.md).
pub const AMBIENT: f64 = 0.55;
/// Diffuse intensity of the directional lights along (1, 1, −1) and (0, 0, −1).
pub const LIGHT_DIFFUSE: [f64; 2] = [0.2, 0.25];
/// Specular intensity of both directional lights.
pub const LIGHT_SPECULAR: f64 = 0.1;

/// The table model's visual shapes (empty if the model is missing or malformed: the table
/// is then drawn as its collision box).
fn table_visuals() -> Vec<super::urdf::Shape> {
    crate::models::text(TABLE_MODEL)
        .ok()
        .and_then(|t| super::urdf::visuals_of(t, TABLE_MODEL).ok())
        .unwrap_or_default()
}

fn visual(e: Element, rgba: &Rgba, group: i32) -> Element {
    e.attr("contype", 0)
        .attr("conaffinity", 0)
        .attr("density", 0)
        .attr("group", group)
        .attr("rgba", nums(rgba))
}

/// A peg body (free joint and collision box named `name`, two drawn half-boxes).
fn peg_body(
    name: &str,
    half_length: f64,
    half_width: f64,
    rgba: [Rgba; 2],
    pos: [f64; 3],
) -> Element {
    let half_part = half_length / 2.0;
    let mut body = Element::new("body")
        .attr("name", name)
        .attr_nums("pos", &pos)
        .child(Element::new("freejoint").attr("name", name))
        .child(
            Element::new("geom")
                .attr("name", name)
                .attr("type", "box")
                .attr_nums("size", &[half_length, half_width, half_width])
                .attr("density", DENSITY)
                .attr("rgba", "0 0 0 0")
                .attr("group", super::GROUP_COLLISION),
        );
    for (k, (x, colour)) in [-half_part, half_part].into_iter().zip(rgba).enumerate() {
        body.push(visual(
            Element::new("geom")
                .attr("name", format!("{name}_visual{k}"))
                .attr("type", "box")
                .attr_nums("pos", &[x, 0.0, 0.0])
                .attr_nums("size", &[half_part, half_width, half_width]),
            &colour,
            0,
        ));
    }
    body
}

/// A kinematic (mocap) body `name` of colliding boxes `(centre, half extents)` named `name_k`.
fn kinematic_boxes(name: &str, boxes: &[([f64; 3], [f64; 3])], rgba: Rgba) -> Element {
    let mut body = Element::new("body")
        .attr("name", name)
        .attr("mocap", "true");
    for (k, (c, h)) in boxes.iter().enumerate() {
        body.push(
            Element::new("geom")
                .attr("name", format!("{name}_{k}"))
                .attr("type", "box")
                .attr_nums("pos", c)
                .attr_nums("size", h)
                .attr("rgba", nums(&rgba)),
        );
    }
    body
}

/// The token inertial of a kinematic body (a mocap body, never simulated), like SAPIEN's
/// shapeless links: MuJoCo cannot place the centre of mass of several massless geoms, and a
/// body whose geoms are resized in place keeps the same compiled mass.
fn token_inertial() -> Element {
    Element::new("inertial")
        .attr("pos", "0 0 0")
        .attr("mass", super::xml::num(super::MASSLESS))
        .attr_nums("diaginertia", &[super::MASSLESS; 3])
}

/// Mass and principal moments (along its axes) of a box peg of half extents
/// (half_length, half_width, half_width) at the props' density, as SAPIEN derives them
/// from its collision box (ManiSkill's pegs).
pub fn peg_inertia(half_length: f64, half_width: f64) -> (f64, [f64; 3]) {
    let (l, w) = (2.0 * half_length, 2.0 * half_width);
    let mass = DENSITY * l * w * w;
    let side = mass / 12.0 * (l * l + w * w);
    (mass, [mass / 12.0 * (2.0 * w * w), side, side])
}

/// The four boxes `(centre, half extents)` of ManiSkill's `_build_box_with_hole`: a square
/// tube along x of half length `depth` and half width `outer_radius` around a square hole of
/// half width `inner_radius`, the hole's centre offset by `center` (y, z) from the tube's.
/// Each wall is as thick as ManiSkill makes it, `(outer − inner)/2` shifted by half the
/// offset, so the walls on the two sides of an off-centre hole differ.
pub fn box_with_hole(
    inner_radius: f64,
    outer_radius: f64,
    depth: f64,
    center: [f64; 2],
) -> [([f64; 3], [f64; 3]); 4] {
    let thickness = (outer_radius - inner_radius) * 0.5;
    let half_center = [center[0] * 0.5, center[1] * 0.5];
    let offset = thickness + inner_radius;
    [
        (
            [0.0, offset + half_center[0], 0.0],
            [depth, thickness - half_center[0], outer_radius],
        ),
        (
            [0.0, -offset + half_center[0], 0.0],
            [depth, thickness + half_center[0], outer_radius],
        ),
        (
            [0.0, 0.0, offset + half_center[1]],
            [depth, outer_radius, thickness - half_center[1]],
        ),
        (
            [0.0, 0.0, -offset + half_center[1]],
            [depth, outer_radius, thickness + half_center[1]],
        ),
    ]
}

/// Centre of mass and principal moments (about it, along the body's axes) of boxes
/// `(centre, half extents)` of one uniform density and total mass `mass`, as SAPIEN derives a
/// builder's inertia from its collision boxes. The boxes are axis-aligned; the products of
/// inertia vanish when the union is mirror-symmetric about two of the body's planes through
/// its centre of mass (PushT's T is, about x = 0 and z = 0).
pub fn box_union_inertia(boxes: &[([f64; 3], [f64; 3])], mass: f64) -> ([f64; 3], [f64; 3]) {
    let volume = |h: &[f64; 3]| 8.0 * h[0] * h[1] * h[2];
    let total: f64 = boxes.iter().map(|(_, h)| volume(h)).sum();
    let masses: Vec<f64> = boxes
        .iter()
        .map(|(_, h)| mass * volume(h) / total)
        .collect();
    let mut com = [0.0; 3];
    for ((c, _), m) in boxes.iter().zip(&masses) {
        for k in 0..3 {
            com[k] += m * c[k] / mass;
        }
    }
    let mut inertia = [0.0; 3];
    for ((c, h), m) in boxes.iter().zip(&masses) {
        let d = [c[0] - com[0], c[1] - com[1], c[2] - com[2]];
        let e = [2.0 * h[0], 2.0 * h[1], 2.0 * h[2]];
        for (k, i) in inertia.iter_mut().enumerate() {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            *i += m * (e[a] * e[a] + e[b] * e[b]) / 12.0 + m * (d[a] * d[a] + d[b] * d[b]);
        }
    }
    (com, inertia)
}

impl Scene {
    /// The static table scene as ManiSkill draws it (docs/rendering.md): the table-workspace
    /// box (top face at z = 0; collision only) with the table model of `models/scene/` drawn
    /// at ManiSkill's pose and scale, the ground plane at [`GROUND_Z`] with the grid texture
    /// (one tile per 4 m), ManiSkill's lights (ambient 0.3, directional along (1, 1, −1)
    /// and (0, 0, −1)) and a black background.
    pub fn add_table_scene(&mut self) {
        let table_rot = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let table_pose = Isometry3::from_parts(
            Translation3::new(TABLE_POS[0], TABLE_POS[1], TABLE_POS[2] + TABLE_HALF[2]),
            table_rot,
        );
        // The ambient light rides on the first directional light: OpenGL adds a light's
        // ambient term whatever its direction, so this is the headlight's ambient without a
        // third light to evaluate at every vertex (the headlight is off).
        for (name, dir, diffuse, ambient) in [
            ("dir1", [1.0, 1.0, -1.0], LIGHT_DIFFUSE[0], AMBIENT),
            ("dir2", [0.0, 0.0, -1.0], LIGHT_DIFFUSE[1], 0.0),
        ] {
            self.worldbody().push(
                Element::new("light")
                    .attr("name", name)
                    .attr("directional", "true")
                    .attr("castshadow", "false")
                    .attr_nums("pos", &[-dir[0], -dir[1], 2.0])
                    .attr_nums("dir", &dir)
                    .attr_nums("diffuse", &[diffuse; 3])
                    .attr_nums("specular", &[LIGHT_SPECULAR; 3])
                    .attr_nums("ambient", &[ambient; 3]),
            );
        }
        // The table model, drawn where ManiSkill draws it (its visual is turned a further
        // 90° in the table actor's frame); falls back to drawing the collision box.
        let table_visuals = table_visuals();
        let mut table_box = pose_attrs(Element::new("geom"), &table_pose)
            .attr("name", TABLE)
            .attr("type", "box")
            .attr_nums("size", &TABLE_HALF)
            .attr("contype", CONTACT_TABLE_BOX)
            .attr("conaffinity", CONTACT_TABLE_BOX);
        if table_visuals.is_empty() {
            table_box = table_box.attr("rgba", "0.82 0.72 0.58 1");
        } else {
            table_box = table_box
                .attr("group", super::GROUP_COLLISION)
                .attr("rgba", "0 0 0 0");
        }
        self.worldbody().push(table_box);
        if !table_visuals.is_empty() {
            let actor = Isometry3::from_parts(
                Translation3::new(TABLE_POS[0], TABLE_POS[1], TABLE_POS[2]),
                table_rot,
            );
            // Geoms of the world body (a body of their own would renumber the robot's).
            let files = |f: &str| crate::models::file_near(TABLE_MODEL, f).map(<[u8]>::to_vec);
            for (k, mut shape) in table_visuals.into_iter().enumerate() {
                shape.origin = actor
                    * Isometry3::from_parts(Translation3::identity(), table_rot)
                    * shape.origin;
                if let Ok(g) = self.visual_geom(&shape, &format!("{TABLE}_visual{k}"), 0, &files) {
                    self.worldbody().push(g);
                }
            }
        }
        // The table top as props feel it (see the collision bits in the parent module);
        // collision only, never drawn.
        self.worldbody().push(
            Element::new("geom")
                .attr("name", TABLE_TOP_PLANE)
                .attr("type", "plane")
                .attr_nums("pos", &[0.0, 0.0, 0.0])
                .attr("size", "0 0 1")
                .attr("contype", CONTACT_TABLE_PLANE)
                .attr("conaffinity", CONTACT_TABLE_PLANE)
                .attr("group", super::GROUP_COLLISION)
                .attr("rgba", "0 0 0 0"),
        );
        // Planes collide as infinite planes whatever their size; the size only bounds what is
        // drawn. MuJoCo draws a size-0 ("infinite") plane out to the far clip plane, which
        // costs software rasterisation ~4x the rest of the scene, so the ground is drawn as
        // a 100 m square (ManiSkill's floor) with the grid texture, one tile per 4 m.
        let mut ground = Element::new("geom")
            .attr("name", GROUND)
            .attr("type", "plane")
            .attr_nums("pos", &[0.0, 0.0, GROUND_Z])
            .attr_nums("size", &GROUND_DRAWN_SIZE)
            .attr("contype", CONTACT_GROUND)
            .attr("conaffinity", CONTACT_GROUND);
        match crate::models::file(GROUND_TEXTURE) {
            Some(png) => {
                self.assets.push(("ground_grid.png".into(), png.to_vec()));
                self.section("asset").push(
                    Element::new("texture")
                        .attr("name", "ground_grid")
                        .attr("type", "2d")
                        .attr("file", "ground_grid.png"),
                );
                self.section("asset").push(
                    Element::new("material")
                        .attr("name", "ground_grid")
                        .attr("texture", "ground_grid")
                        .attr("texuniform", "true")
                        .attr_nums("texrepeat", &[0.25, 0.25])
                        .attr_nums("rgba", &GROUND_RGBA)
                        .attr("specular", "0")
                        .attr("shininess", "0"),
                );
                ground = ground.attr("material", "ground_grid");
            }
            None => ground = ground.attr("rgba", "0.45 0.47 0.5 1"),
        }
        self.worldbody().push(ground);
        let vis = self.section("visual");
        vis.push(
            Element::new("headlight")
                .attr("active", 0)
                .attr_nums("ambient", &[0.0; 3])
                .attr_nums("diffuse", &[0.0, 0.0, 0.0])
                .attr_nums("specular", &[0.0, 0.0, 0.0]),
        );
        // ManiSkill's background is black: no haze where the floor meets the horizon.
        vis.push(Element::new("rgba").attr("haze", "0 0 0 1"));
    }

    /// A dynamic box (free joint named `name`) with half extents `half`, at `pos`.
    pub fn add_box(&mut self, name: &str, half: [f64; 3], rgba: Rgba, pos: [f64; 3]) {
        let geom = Element::new("geom")
            .attr("type", "box")
            .attr_nums("size", &half);
        self.add_free_body(name, pos, rgba, geom);
    }

    /// A body with a free joint and one geom, all named `name`, with the props' density.
    fn add_free_body(&mut self, name: &str, pos: [f64; 3], rgba: Rgba, geom: Element) {
        let body = Element::new("body")
            .attr("name", name)
            .attr_nums("pos", &pos)
            .child(Element::new("freejoint").attr("name", name))
            .child(
                geom.attr("name", name)
                    .attr("density", DENSITY)
                    .attr("rgba", nums(&rgba)),
            );
        self.worldbody().push(body);
    }

    /// A dynamic sphere (free joint named `name`) of radius `r`.
    pub fn add_sphere(&mut self, name: &str, r: f64, rgba: Rgba, pos: [f64; 3]) {
        let geom = Element::new("geom")
            .attr("type", "sphere")
            .attr_nums("size", &[r]);
        self.add_free_body(name, pos, rgba, geom);
    }

    /// PokeCube's peg (docs/tasks.md §2.1): one collision box of half extents
    /// (half_length, half_width, half_width) along local x, drawn as two visual half-boxes of
    /// one colour.
    pub fn add_peg(
        &mut self,
        name: &str,
        half_length: f64,
        half_width: f64,
        rgba: Rgba,
        pos: [f64; 3],
    ) {
        let body = peg_body(name, half_length, half_width, [rgba, rgba], pos);
        self.worldbody().push(body);
    }

    /// ManiSkill's `build_twocolor_peg` (LiftPegUpright's red/blue peg): one collision box of
    /// half extents (half_length, half_width, half_width) along local x, drawn as two visual
    /// half-boxes, the −x half in `rgba[0]`, the +x half in `rgba[1]`. Its inertia is given
    /// explicitly (the box's, at the props' density, principal axes along the body's): the
    /// drawn halves would otherwise make MuJoCo diagonalise the box's degenerate inertia
    /// (two equal moments) in the render model but not in the physics model, and a peg turned
    /// off its axes would step differently in the two at the last bits.
    pub fn add_twocolor_peg(
        &mut self,
        name: &str,
        half_length: f64,
        half_width: f64,
        rgba: [Rgba; 2],
        pos: [f64; 3],
    ) {
        let (mass, inertia) = peg_inertia(half_length, half_width);
        let inertial = Element::new("inertial")
            .attr_nums("pos", &[0.0; 3])
            .attr("mass", super::xml::num(mass))
            .attr_nums("diaginertia", &inertia);
        let body = peg_body(name, half_length, half_width, rgba, pos).child(inertial);
        self.worldbody().push(body);
    }

    /// ManiSkill's `_build_box_with_hole` (PegInsertionSide-v1): a kinematic (mocap) body of
    /// the four colliding boxes of [`box_with_hole`], all of colour `rgba`, named `name_k`, at
    /// `pos`. Its token inertial does not depend on the boxes, so that a model whose boxes are
    /// resized in place ([`crate::mujoco::Model::set_box_geom`]) equals one compiled with them.
    pub fn add_box_with_hole(
        &mut self,
        name: &str,
        boxes: &[([f64; 3], [f64; 3]); 4],
        rgba: Rgba,
        pos: [f64; 3],
    ) {
        let body = kinematic_boxes(name, boxes, rgba)
            .attr_nums("pos", &pos)
            .child(token_inertial());
        self.worldbody().push(body);
    }

    /// ManiSkill's un-textured white table (PushT-v1's `WhiteTableSceneBuilder`): every drawn
    /// part of the table model loses its material and is drawn in plain white. Call after
    /// [`Scene::add_table_scene`]; the table's collision geoms are untouched.
    pub fn whiten_table(&mut self) {
        let prefix = format!("{TABLE}_visual");
        for g in self.worldbody().children.iter_mut() {
            let is_table = g.name == "geom"
                && g.attrs
                    .iter()
                    .any(|(k, v)| k == "name" && v.starts_with(&prefix));
            if is_table {
                g.attrs.retain(|(k, _)| k != "material");
                g.set("rgba", nums(&WHITE));
            }
        }
    }

    /// A body made of boxes `(centre, half extents)` in its frame, all of colour `rgba`: a
    /// dynamic prop (free joint named `name`) of total mass `mass` (kg) and friction
    /// `friction` when `mass` is `Some((mass, friction))`, its boxes colliding and drawn (one
    /// collision box `name_k` and one drawn box `name_visualk` each; the mass spread over the
    /// boxes' volume, so the centre of mass and inertia are the union's, as SAPIEN's
    /// `builder._mass`); a visual-only marker on a mocap body when `None` (PushT-v1's T and
    /// its goal).
    pub fn add_box_union(
        &mut self,
        name: &str,
        boxes: &[([f64; 3], [f64; 3])],
        rgba: Rgba,
        mass: Option<(f64, f64)>,
        pos: [f64; 3],
    ) {
        let mut body = Element::new("body").attr("name", name);
        match mass {
            Some((mass, friction)) => {
                let (com, inertia) = box_union_inertia(boxes, mass);
                body = body
                    .attr_nums("pos", &pos)
                    .child(Element::new("freejoint").attr("name", name))
                    .child(
                        Element::new("inertial")
                            .attr_nums("pos", &com)
                            .attr("mass", super::xml::num(mass))
                            .attr_nums("diaginertia", &inertia),
                    );
                let friction = [friction, TORSIONAL_ROLLING[0], TORSIONAL_ROLLING[1]];
                for (k, (c, h)) in boxes.iter().enumerate() {
                    body.push(
                        Element::new("geom")
                            .attr("name", format!("{name}_{k}"))
                            .attr("type", "box")
                            .attr_nums("pos", c)
                            .attr_nums("size", h)
                            .attr_nums("friction", &friction)
                            .attr("rgba", "0 0 0 0")
                            .attr("group", super::GROUP_COLLISION),
                    );
                }
            }
            None => {
                body = body.attr("mocap", "true").child(token_inertial());
            }
        }
        for (k, (c, h)) in boxes.iter().enumerate() {
            body.push(visual(
                Element::new("geom")
                    .attr("name", format!("{name}_visual{k}"))
                    .attr("type", "box")
                    .attr_nums("pos", c)
                    .attr_nums("size", h),
                &rgba,
                0,
            ));
        }
        self.worldbody().push(body);
    }

    /// A visual-only marker disc on a mocap body: a cylinder of radius `radius` and half
    /// length `half_length` along the body's local **x** (as SAPIEN builds cylinders; see
    /// [`Scene::add_marker_target`]). Seen by sensor cameras.
    pub fn add_marker_disc(&mut self, name: &str, radius: f64, half_length: f64, rgba: Rgba) {
        self.add_marker_target(name, &[(radius, half_length, rgba)]);
    }

    /// A kinematic (mocap) body made of boxes `(centre, half extents)` that collide.
    pub fn add_kinematic_boxes(&mut self, name: &str, boxes: &[([f64; 3], [f64; 3])], rgba: Rgba) {
        self.worldbody().push(kinematic_boxes(name, boxes, rgba));
    }

    /// A visual-only marker sphere on a mocap body. `hidden` puts it in the group that sensor
    /// cameras do not draw (ManiSkill's `_hidden_objects`).
    pub fn add_marker_sphere(&mut self, name: &str, r: f64, rgba: Rgba, hidden: bool) {
        let group = if hidden { GROUP_HIDDEN } else { 0 };
        let body = Element::new("body")
            .attr("name", name)
            .attr("mocap", "true")
            .child(visual(
                Element::new("geom")
                    .attr("name", name)
                    .attr("type", "sphere")
                    .attr_nums("size", &[r]),
                &rgba,
                group,
            ));
        self.worldbody().push(body);
    }

    /// A visual-only marker made of coaxial cylinders `(radius, half length, colour)` with
    /// their axis along the body's local **x**, as SAPIEN builds cylinders (each MuJoCo
    /// cylinder, natively along z, is turned by +90° about y), so a body pose copied from
    /// ManiSkill places it identically (PokeCube's red/white target). Seen by sensor cameras.
    pub fn add_marker_target(&mut self, name: &str, rings: &[(f64, f64, Rgba)]) {
        // Massless geoms: MuJoCo cannot place the centre of mass of several of them, so the
        // (kinematic, never simulated) body gets a token inertial like SAPIEN's shapeless links.
        let mut body = Element::new("body")
            .attr("name", name)
            .attr("mocap", "true")
            .child(token_inertial());
        for (k, (r, hl, rgba)) in rings.iter().enumerate() {
            body.push(visual(
                Element::new("geom")
                    .attr("name", format!("{name}_{k}"))
                    .attr("type", "cylinder")
                    .attr_nums("quat", &[FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2, 0.0])
                    .attr_nums("size", &[*r, *hl]),
                rgba,
                0,
            ));
        }
        self.worldbody().push(body);
    }

    /// A fixed camera. `pos`/`quat` are the MuJoCo camera frame (looks along −z, y up).
    pub fn add_camera(&mut self, name: &str, pos: [f64; 3], quat: [f64; 4], fovy_deg: f64) {
        self.worldbody().push(
            Element::new("camera")
                .attr("name", name)
                .attr_nums("pos", &pos)
                .attr_nums("quat", &quat)
                .attr("fovy", super::xml::num(fovy_deg)),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mujoco::{Data, ObjType};
    use std::sync::Arc;

    #[test]
    fn table_top_is_at_zero_and_box_masses_follow_density() {
        let mut s = Scene::new("t", crate::mjcf::TIMESTEP);
        s.add_table_scene();
        s.add_box("cube", [0.02; 3], [1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.1]);
        s.add_peg("peg", 0.12, 0.025, [0.0, 0.0, 1.0, 1.0], [0.3, 0.0, 0.1]);
        s.add_sphere("sphere", 0.02, [0.0, 0.0, 1.0, 1.0], [-0.3, 0.0, 0.1]);
        s.add_marker_sphere("goal", 0.025, [0.0, 1.0, 0.0, 1.0], true);
        let m = Arc::new(s.finish().compile().unwrap());
        let cube = m.require_id(ObjType::Body, "cube").unwrap();
        let peg = m.require_id(ObjType::Body, "peg").unwrap();
        let sphere = m.require_id(ObjType::Body, "sphere").unwrap();
        assert!(
            (m.body_mass()[cube] - 0.064).abs() < 1e-12,
            "{}",
            m.body_mass()[cube]
        );
        assert!(
            (m.body_mass()[peg] - 0.6).abs() < 1e-9,
            "{}",
            m.body_mass()[peg]
        );
        assert!(
            (m.body_mass()[sphere] - 0.0335103).abs() < 1e-6,
            "{}",
            m.body_mass()[sphere]
        );
        let mut d = Data::new(m.clone()).unwrap();
        crate::mjcf::apply_weights(&mut d, &crate::mjcf::prop_weights(&m, &[]));
        for _ in 0..1000 {
            d.step();
        }
        // Resting on the table top (z = 0): centre at the half height, within contact softness.
        assert!(
            (d.xpos()[3 * cube + 2] - 0.02).abs() < 1e-3,
            "{}",
            d.xpos()[3 * cube + 2]
        );
        assert!((d.xpos()[3 * peg + 2] - 0.025).abs() < 1e-3);
        // The table is drawn from its shipped model (mesh geoms), not as its collision box.
        assert!(!table_visuals().is_empty());
        m.require_id(ObjType::Geom, &format!("{TABLE}_visual0"))
            .unwrap();
        // The goal marker is a mocap body that does not fall.
        let goal = m.require_id(ObjType::Body, "goal").unwrap();
        assert_eq!(m.body_mocapid()[goal], 0);
    }

    #[test]
    fn the_twocolor_peg_has_the_box_inertia_and_its_two_colours() {
        let (a, b) = ([1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]);
        let mut s = Scene::new("t", crate::mjcf::TIMESTEP);
        s.add_table_scene();
        s.add_twocolor_peg("peg", 0.12, 0.025, [a, b], [0.0, 0.0, 0.1]);
        let m = Arc::new(s.finish().compile().unwrap());
        let peg = m.require_id(ObjType::Body, "peg").unwrap();
        assert!((m.body_mass()[peg] - 0.6).abs() < 1e-12);
        // (m/12)(w² + w²) about the long axis, (m/12)(l² + w²) about the others.
        let i = &m.body_inertia()[3 * peg..3 * peg + 3];
        for (got, want) in i.iter().zip([2.5e-4, 3.005e-3, 3.005e-3]) {
            assert!((got - want).abs() < 1e-12, "{i:?}");
        }
        for (k, rgba) in [a, b].iter().enumerate() {
            let g = m
                .require_id(ObjType::Geom, &format!("peg_visual{k}"))
                .unwrap();
            let got: Vec<f64> = m.geom_rgba()[4 * g..4 * g + 4]
                .iter()
                .map(|&x| x as f64)
                .collect();
            assert_eq!(got, rgba.to_vec(), "half {k}");
            // The −x half first.
            let x = m.geom_pos()[3 * g];
            assert!(
                (x - (k as f64 - 0.5) * 0.12).abs() < 1e-12,
                "half {k} at {x}"
            );
        }
    }
}
