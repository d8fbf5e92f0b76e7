//! Unit tests of [`super`] (visual mesh conversion).
use super::*;

fn cube_part() -> Part {
    // A unit cube as 12 triangles with 8 shared vertices.
    let positions: Vec<[f32; 3]> = (0..8)
        .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let indices = quads
        .iter()
        .flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]])
        .collect();
    Part {
        material: 0,
        positions,
        normals: None,
        uvs: None,
        indices,
    }
}

#[test]
fn cube_obj_has_crease_normals_and_mujoco_loads_it() {
    let (obj, n) = obj_text(&cube_part());
    assert_eq!(n, 12);
    // The 90° edges are creases: every normal is an axis.
    for line in obj.lines().filter(|l| l.starts_with("vn ")) {
        let v: Vec<f32> = line[3..].split(' ').map(|x| x.parse().unwrap()).collect();
        let ones = v.iter().filter(|x| (x.abs() - 1.0).abs() < 1e-6).count();
        assert_eq!(ones, 1, "{line}");
    }
    mujoco_accepts(&obj).unwrap();
}

#[test]
fn repeated_triangles_are_dropped_and_repeated_edges_split() {
    let mut p = cube_part();
    let first: Vec<u32> = p.indices[..3].to_vec();
    p.indices.extend(&first); // the same triangle again
    p.indices.extend([first[0], first[1], 7]); // reuses the directed edge (0, 2)
    let (obj, n) = obj_text(&p);
    assert_eq!(n, 13);
    mujoco_accepts(&obj).unwrap();
}

#[test]
fn simplify_meets_the_budget_on_a_dense_sphere() {
    let mut p = Part::default();
    let (nu, nv) = (64, 32);
    for j in 0..=nv {
        for i in 0..=nu {
            let (th, ph) = (
                std::f32::consts::PI * j as f32 / nv as f32,
                2.0 * std::f32::consts::PI * i as f32 / nu as f32,
            );
            p.positions
                .push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    for j in 0..nv {
        for i in 0..nu {
            let a = j * (nu + 1) + i;
            let b = a + nu + 1;
            p.indices.extend([a, b, a + 1, a + 1, b, b + 1]);
        }
    }
    let s = simplify(&p, 500, None);
    assert!(s.indices.len() / 3 <= 500, "{}", s.indices.len() / 3);
    assert!(s.indices.len() / 3 >= 100);
    // A tight bound keeps more triangles than the budget, with every vertex on the sphere.
    let fine = simplify(&p, 500, Some(0.001));
    assert!(fine.indices.len() / 3 > 1000, "{}", fine.indices.len() / 3);
    for v in &fine.positions {
        let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        assert!((r - 1.0).abs() < 1e-5, "{r}");
    }
}

#[test]
fn splice_replaces_visuals_of_named_links_only() {
    let model = "<robot name=\"r\">\n  <link name=\"a\">\n    <visual><geometry><box size=\"1 1 1\"/></geometry></visual>\n    <collision/>\n  </link>\n  <link name=\"b\"/>\n  <link name=\"c\">\n    <visual><geometry><box size=\"1 1 1\"/></geometry></visual>\n  </link>\n</robot>\n";
    let out = splice_visuals(
        model,
        &[
            ("a".into(), vec!["<visual>A</visual>".into()]),
            ("b".into(), vec!["<visual>B</visual>".into()]),
        ],
    )
    .unwrap();
    assert!(
        out.contains("<link name=\"a\">\n    <visual>A</visual>\n    <collision/>"),
        "{out}"
    );
    assert!(
        out.contains("<link name=\"b\">\n    <visual>B</visual>\n  </link>"),
        "{out}"
    );
    assert!(
        out.contains("<link name=\"c\">\n    <visual><geometry>"),
        "{out}"
    );
    assert_eq!(out.matches("<visual").count(), 3);
    let e = splice_visuals(model, &[("zz".into(), vec![])]).unwrap_err();
    assert!(e.contains("zz"), "{e}");
}
