//! The command line's scene export (`export-mjcf`, checked by Debian's independent
//! `mujoco-compile` and by mjskill's MuJoCo) and mesh fitting (`fit-primitives`), per robot.
#![cfg(feature = "cli")]
mod common;

use mjskill::mujoco::ObjType;

#[test]
fn export_mjcf_of_fetch_is_accepted_by_debians_mujoco_compile() {
    let printed = common::export_and_mujoco_compile("fetch", &["export-mjcf", "--robot", "fetch"]);
    assert!(
        printed.contains("root_z_rotation_joint") && printed.contains("drive_root_x_axis_joint")
    );
}

#[test]
fn export_mjcf_is_accepted_by_debians_mujoco_compile() {
    let printed = common::export_and_mujoco_compile(
        "pickcube_panda",
        &["export-mjcf", "--robot", "panda", "--env", "PickCube-v1"],
    );
    assert!(
        printed.contains("panda_joint7") && printed.contains("cube"),
        "compiled model lists the robot and the cube"
    );
    // Unknown robot: a clear error listing the valid ones, non-zero exit.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(["export-mjcf", "--robot", "ur5"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ur5") && err.contains("panda"), "{err}");
}

#[test]
fn so100_export_mjcf_writes_a_scene_mujoco_compiles() {
    let m = common::export_mjcf_model("so100", "PickCubeSO100-v1");
    assert!(m.id(ObjType::Joint, "wrist_roll").is_some());
    assert!(m.id(ObjType::Body, "cube").is_some());
}

#[test]
fn widowxai_export_mjcf_writes_a_scene_mujoco_compiles() {
    let m = common::export_mjcf_model("widowxai", "PickCubeWidowXAI-v1");
    assert!(m.id(ObjType::Joint, "left_carriage_joint").is_some());
    assert!(m.id(ObjType::Body, "cube").is_some());
}

#[cfg(feature = "mesh-tools")]
#[test]
fn fit_primitives_scales_millimetre_meshes() {
    // A 10 mm cube as an ASCII STL (12 triangles), as the Robotiq meshes are in millimetres.
    let v = |i: usize| {
        [
            10.0 * (i & 1) as f64,
            10.0 * ((i >> 1) & 1) as f64,
            10.0 * ((i >> 2) & 1) as f64,
        ]
    };
    let faces = [
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 5, 7],
        [1, 7, 3],
    ];
    let mut stl = String::from("solid cube\n");
    for f in faces {
        stl += "facet normal 0 0 0\nouter loop\n";
        for i in f {
            let p = v(i);
            stl += &format!("vertex {} {} {}\n", p[0], p[1], p[2]);
        }
        stl += "endloop\nendfacet\n";
    }
    stl += "endsolid cube\n";
    let path = common::scratch("mm-cube.stl");
    std::fs::write(&path, stl).unwrap();
    let run = |scale: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mjskill-meshes"))
            .args([
                "fit-primitives",
                "--shape",
                "box",
                "--scale",
                scale,
                "--mesh",
            ])
            .arg(&path)
            .output()
            .unwrap()
    };
    let out = run("0.001");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(text.contains(r#"<box size="0.01 0.01 0.01"/>"#), "{text}");
    assert!(text.contains(r#"xyz="0.005 0.005 0.005""#), "{text}");
    let out = run("0");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--scale must be a positive number, got 0"),
        "{err}"
    );
    std::fs::remove_file(&path).ok();
}
