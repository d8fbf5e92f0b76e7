//! ManiSkill's segmentation ids for an env's scene, and the table that maps every MuJoCo geom
//! to one of them (built once per env; the renderer looks labels up by geom id).
//!
//! ManiSkill numbers the objects of a scene in the order it builds them (`per_scene_id`,
//! 0 = background): the robot's links first (the articulation's links, depth first in URDF
//! joint order), then the table scene's actors (`table-workspace`, `ground`), then the task's
//! actors in build order (hidden ones such as `goal_site` included, though sensor cameras
//! never see them). mjskill's robot bodies are the URDF links built depth first in the same
//! order, so the robot bodies sorted by body id give the link ids (named by their URDF link;
//! the xArm6's root `world` is `xarm6_world` in mjskill, as MuJoCo reserves `world`).
//!
//! Every geom takes the id of its body, or of the nearest ancestor body that has one (a
//! visual mesh, a prop's visual parts). Geoms of the world body belong to the table or the
//! ground by name: `table-workspace` / `ground` itself or a name beginning with it followed by
//! a non-alphanumeric character (`table-workspace_visual0`, `ground/tile`). Whether a geom
//! is drawn is the renderer's business (geom groups), not the table's.
use crate::mjcf::{GROUND, TABLE};
use crate::mujoco::{BodyId, Model, ObjType};

/// The segmentation ids of an env and the geom → id table.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SegmentationIds {
    /// Object names by id; `names[0]` is the background (`""`).
    pub names: Vec<String>,
    /// Id of every model geom (0: none).
    pub geom_labels: Vec<i16>,
}

/// Whether `name` is `actor` or `actor` followed by a non-alphanumeric separator.
fn named_for(name: &str, actor: &str) -> bool {
    name.strip_prefix(actor)
        .is_some_and(|rest| rest.is_empty() || !rest.starts_with(|c: char| c.is_alphanumeric()))
}

impl SegmentationIds {
    /// The ids of a scene with the robot links `links` (URDF name and body, any order) and
    /// the task actors `actors` (ManiSkill's build order; bodies of the same name). Actors
    /// the model lacks keep their id but label no geom.
    pub(crate) fn new(
        model: &Model,
        links: &[(String, BodyId)],
        actors: &[&str],
    ) -> SegmentationIds {
        let mut links: Vec<(usize, &str)> =
            links.iter().map(|(n, b)| (b.index(), n.as_str())).collect();
        links.sort_unstable();
        links.dedup_by_key(|l| l.0);
        let mut names = vec![String::new()];
        let mut body_label = vec![0i16; model.nbody()];
        let parent = model.body_parentid();
        for (b, name) in links {
            body_label[b] = names.len() as i16;
            // MuJoCo reserves the body name "world": a root link of that name is kept as
            // `<robot>_world` in mjskill's robot files (the xArm6's), ManiSkill's `world`.
            let world = parent[b] == 0 && name.ends_with("_world");
            names.push(if world { "world" } else { name }.to_string());
        }
        let table = names.len() as i16;
        names.push(TABLE.to_string());
        let ground = names.len() as i16;
        names.push(GROUND.to_string());
        for a in actors {
            if let Some(b) = model.id(ObjType::Body, a).filter(|&b| b != 0) {
                body_label[b] = names.len() as i16;
            }
            names.push(a.to_string());
        }
        let geom_body = model.geom_bodyid();
        let geom_labels = (0..model.ngeom())
            .map(|g| {
                let mut b = geom_body[g] as usize;
                while b != 0 && body_label[b] == 0 {
                    b = parent[b] as usize;
                }
                if b != 0 {
                    return body_label[b];
                }
                let name = model.name(ObjType::Geom, g);
                if named_for(&name, TABLE) {
                    table
                } else if named_for(&name, GROUND) {
                    ground
                } else {
                    0
                }
            })
            .collect();
        SegmentationIds { names, geom_labels }
    }

    /// `(id, name)` of every object, background excluded (ManiSkill's `segmentation_id_map`).
    pub(crate) fn id_map(&self) -> Vec<(i16, &str)> {
        self.names
            .iter()
            .enumerate()
            .skip(1)
            .map(|(i, n)| (i as i16, n.as_str()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_geoms_belong_to_the_table_or_ground_by_name() {
        assert!(named_for("table-workspace", TABLE));
        assert!(named_for("table-workspace_visual0", TABLE));
        assert!(named_for("ground/tile", GROUND));
        assert!(!named_for("table-top", TABLE));
        assert!(!named_for("grounded", GROUND));
    }

    #[test]
    fn geoms_take_the_id_of_their_nearest_labelled_body() {
        let xml = r#"<mujoco><worldbody>
            <geom name="table-workspace" type="box" size="1 1 0.1"/>
            <geom name="ground" type="plane" size="5 5 1"/>
            <geom name="table-top" type="plane" size="5 5 1"/>
            <body name="link0"><geom name="l0" size="0.1"/>
              <body name="link1"><geom size="0.1"/>
                <body name="pad"><geom size="0.05"/></body>
              </body>
            </body>
            <body name="cube" pos="1 0 0"><freejoint/><geom size="0.1"/>
              <body name="cube_visual"><geom size="0.1"/></body>
            </body>
        </worldbody></mujoco>"#;
        let m = Model::from_xml_string(xml, &[]).unwrap();
        let b = |n: &str| m.require_body(n).unwrap();
        // Robot bodies given out of order: ids follow the body order.
        let links = [
            ("link1".to_string(), b("link1")),
            ("r_world".into(), b("link0")),
        ];
        let ids = SegmentationIds::new(&m, &links, &["cube", "goal_site"]);
        assert_eq!(
            ids.id_map(),
            [
                (1, "world"),
                (2, "link1"),
                (3, "table-workspace"),
                (4, "ground"),
                (5, "cube"),
                (6, "goal_site")
            ]
        );
        // Geoms in model order: table, ground, table-top, link0, link1, pad (→ link1), cube,
        // cube_visual (→ cube).
        assert_eq!(ids.geom_labels, [3, 4, 0, 1, 2, 2, 5, 5]);
    }
}
