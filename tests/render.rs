//! Headless rendering: sensor images in the rgb/depth/rgbd obs modes and the human render,
//! checked against projections computed independently from the camera pose and intrinsics.
#![cfg(feature = "cli")]

mod common;
use mjskill::mujoco::ObjType;
use mjskill::{make, Env, EnvConfig, ObsMode};
use nalgebra::{Matrix3, Vector3};

fn env(mode: ObsMode, seed: u64) -> Env {
    let mut e = make(
        "PickCube-v1",
        EnvConfig {
            obs_mode: mode,
            ..Default::default()
        },
    )
    .expect("rendering must be available (bash .ci/setup installs EGL/Mesa)");
    e.reset(Some(seed));
    e
}

/// Pinhole camera of a MuJoCo camera: pose from cam_xpos/cam_xmat, vertical fovy.
struct Pinhole {
    pos: Vector3<f64>,
    /// Columns: right, up, backward (MuJoCo cameras look along −z).
    rot: Matrix3<f64>,
    f: f64,
    w: usize,
    h: usize,
}

impl Pinhole {
    fn of(env: &Env, name: &str, size: (usize, usize)) -> Pinhole {
        let m = env.model();
        let id = m.require_id(ObjType::Camera, name).unwrap();
        let d = env.data();
        let p = &d.cam_xpos()[3 * id..3 * id + 3];
        let r = &d.cam_xmat()[9 * id..9 * id + 9];
        let fovy = m.cam_fovy()[id].to_radians();
        Pinhole {
            pos: Vector3::new(p[0], p[1], p[2]),
            rot: Matrix3::from_row_slice(r),
            f: size.1 as f64 / 2.0 / (fovy / 2.0).tan(),
            w: size.0,
            h: size.1,
        }
    }

    /// Pixel (column, row) containing the projection of world point `x` (top row 0).
    fn project(&self, x: Vector3<f64>) -> (usize, usize) {
        let c = self.rot.transpose() * (x - self.pos);
        assert!(c.z < 0.0, "point behind the camera");
        let u = self.w as f64 / 2.0 + self.f * c.x / -c.z;
        let v = self.h as f64 / 2.0 - self.f * c.y / -c.z;
        assert!(
            u >= 0.0 && v >= 0.0 && u < self.w as f64 && v < self.h as f64,
            "projection ({u}, {v}) outside the image"
        );
        (u as usize, v as usize)
    }

    /// World direction of the ray through the centre of pixel (col, row), scaled so that its
    /// component along the optical axis is 1.
    fn ray(&self, col: usize, row: usize) -> Vector3<f64> {
        let x = (col as f64 + 0.5 - self.w as f64 / 2.0) / self.f;
        let y = (self.h as f64 / 2.0 - (row as f64 + 0.5)) / self.f;
        self.rot * Vector3::new(x, y, -1.0)
    }
}

fn body(env: &Env, name: &str) -> (Vector3<f64>, Matrix3<f64>) {
    let b = env.model().require_id(ObjType::Body, name).unwrap();
    let d = env.data();
    let p = &d.xpos()[3 * b..3 * b + 3];
    (
        Vector3::new(p[0], p[1], p[2]),
        Matrix3::from_row_slice(&d.xmat()[9 * b..9 * b + 9]),
    )
}

fn pixel(rgb: &[u8], w: usize, (col, row): (usize, usize)) -> [u8; 3] {
    let i = 3 * (row * w + col);
    [rgb[i], rgb[i + 1], rgb[i + 2]]
}

fn is_red(p: [u8; 3]) -> bool {
    p[0] > 100 && p[1] < 60 && p[2] < 60
}

fn is_green(p: [u8; 3]) -> bool {
    p[1] > 100 && p[0] < 60 && p[2] < 60
}

/// Ray parameter where `origin + t·dir` enters the box (centre `c`, rotation `r`, half size `h`).
fn ray_box(
    origin: Vector3<f64>,
    dir: Vector3<f64>,
    c: Vector3<f64>,
    r: Matrix3<f64>,
    h: f64,
) -> f64 {
    let (o, d) = (r.transpose() * (origin - c), r.transpose() * dir);
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        let (a, b) = ((-h - o[k]) / d[k], (h - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    assert!(t0 <= t1 && t0 > 0.0, "the ray misses the box");
    t0
}

#[test]
fn cube_is_red_at_its_projection_and_depth_matches_the_ray() {
    let e = env(ObsMode::Rgbd, 0);
    let cam = e.image("base_camera").expect("sensor camera images");
    let (w, h) = (cam.width, cam.height);
    assert_eq!((w, h), (128, 128));
    let pin = Pinhole::of(&e, "base_camera", (w, h));
    let (cube, rot) = body(&e, "cube");
    let px = pin.project(cube);
    let rgb = cam.rgb.unwrap();
    assert!(
        is_red(pixel(rgb, w, px)),
        "pixel {px:?} = {:?}",
        pixel(rgb, w, px)
    );
    // A pixel well away from the cube is not red (the test is not fooled by a red image).
    let far = ((px.0 + w / 2) % w, (px.1 + h / 2) % h);
    assert!(!is_red(pixel(rgb, w, far)));
    // Depth = distance along the optical axis to where the pixel's ray meets the cube.
    let t = ray_box(pin.pos, pin.ray(px.0, px.1), cube, rot, 0.02);
    let depth = cam.depth.unwrap()[px.1 * w + px.0] as f64;
    assert!((depth - t).abs() < 0.005, "depth {depth} vs ray {t}");
    // And the table top around it is farther than the cube's face.
    assert!(t > 0.2 && t < 1.0, "{t}");
}

#[test]
fn goal_marker_hidden_from_sensor_but_drawn_for_humans() {
    let mut e = env(ObsMode::Rgb, 0);
    // Put the goal where both cameras see it unoccluded (mocap pose in the physics state).
    let mut s = e.get_state();
    let n = s.physics.len();
    s.physics[n - 7..n - 4].copy_from_slice(&[0.1, -0.15, 0.05]);
    e.set_state(&s).unwrap();
    let (goal, _) = body(&e, "goal_site");
    assert!((goal - Vector3::new(0.1, -0.15, 0.05)).norm() < 1e-12);

    let (sensor, human) = e.cameras();
    let pin = Pinhole::of(&e, sensor.name, sensor.size);
    let px = pin.project(goal);
    let rgb = e.sensor_rgb().unwrap();
    let p = pixel(rgb, sensor.size.0, px);
    assert!(
        !is_green(p),
        "goal visible in the sensor image at {px:?}: {p:?}"
    );
    assert!(!rgb.chunks(3).any(|c| is_green([c[0], c[1], c[2]])));

    let pin = Pinhole::of(&e, human.name, human.size);
    let px = pin.project(goal);
    let frame = e.render().unwrap();
    assert_eq!(frame.len(), 512 * 512 * 3);
    let p = pixel(frame, human.size.0, px);
    assert!(
        is_green(p),
        "goal not drawn in the human render at {px:?}: {p:?}"
    );
}

#[test]
fn same_state_renders_the_same_image() {
    let mut e = env(ObsMode::Rgbd, 3);
    let s = e.get_state();
    let (rgb, depth) = (
        e.sensor_rgb().unwrap().to_vec(),
        e.sensor_depth().unwrap().to_vec(),
    );
    let human = e.render().unwrap().to_vec();
    let a = vec![0.5f32; e.action_space().shape[0]];
    e.step(&a).unwrap();
    assert_ne!(e.sensor_rgb().unwrap(), &rgb[..], "the arm moved");
    assert_ne!(e.render().unwrap(), &human[..]);
    e.set_state(&s).unwrap();
    assert_eq!(e.sensor_rgb().unwrap(), &rgb[..]);
    assert_eq!(e.sensor_depth().unwrap(), &depth[..]);
    assert_eq!(e.render().unwrap(), &human[..]);
    // A second env of the same seed renders identically too.
    let mut f = env(ObsMode::Rgbd, 3);
    assert_eq!(f.sensor_rgb().unwrap(), &rgb[..]);
    assert_eq!(f.render().unwrap(), &human[..]);
}

#[test]
fn visual_obs_modes_have_state_free_vectors_and_images() {
    let state = env(ObsMode::State, 0);
    for (mode, rgb, depth) in [
        (ObsMode::Rgb, true, false),
        (ObsMode::Depth, false, true),
        (ObsMode::Rgbd, true, true),
    ] {
        let mut e = env(mode, 0);
        // agent qpos (9), qvel (9), extras is_grasped, tcp_pose, goal_pos: no object pose.
        assert_eq!(e.obs().len(), 29, "{mode:?}");
        assert_eq!(e.observation_space().shape, vec![29]);
        assert!(e.obs_part("extra/obj_pose").is_none());
        assert_eq!(
            e.obs_part("extra/tcp_pose"),
            state.obs_part("extra/tcp_pose")
        );
        assert_eq!(
            e.sensor_rgb().map(|v| v.len()),
            rgb.then_some(128 * 128 * 3)
        );
        assert_eq!(
            e.sensor_depth().map(|v| v.len()),
            depth.then_some(128 * 128)
        );
        let img = e.image("base_camera").unwrap();
        assert_eq!((img.width, img.height), (128, 128));
        assert!(e.image("render_camera").is_none() && e.image("nope").is_none());
        if let Some(d) = e.sensor_depth() {
            assert!(d.iter().all(|z| z.is_finite() && *z >= 0.01 && *z <= 100.0));
        }
        let a = vec![0.0f32; e.action_space().shape[0]];
        assert_eq!(e.step(&a).unwrap().obs.len(), 29);
    }
    // State modes have no sensor images but can still render for humans.
    let mut s = env(ObsMode::State, 0);
    assert!(s.sensor_rgb().is_none() && s.image("base_camera").is_none());
    assert_eq!(s.render().unwrap().len(), 512 * 512 * 3);
    assert_eq!(s.render_size(), (512, 512));
    assert!(ObsMode::parse("rgbd").unwrap().is_visual());
    assert_eq!(ObsMode::parse("rgb+depth").unwrap(), ObsMode::Rgbd);
    assert!(ObsMode::parse("rgb+dept")
        .unwrap_err()
        .to_string()
        .contains("rgb, depth, segmentation"));
}

#[test]
fn render_options_change_the_image_and_bad_ones_are_rejected() {
    let mut e = env(ObsMode::Rgb, 0);
    let plain = e.render().unwrap().to_vec();
    let mut o = e.render_options();
    assert!(!o.shadows && o.msaa_samples == 0 && !o.reflections);
    o.shadows = true;
    o.msaa_samples = 4;
    e.set_render_options(o).unwrap();
    assert_eq!(e.render_options(), o);
    let fancy = e.render().unwrap().to_vec();
    assert_ne!(plain, fancy);
    let bad = mjskill::mujoco::render::RenderOptions {
        clip: (1.0, 0.5),
        ..o
    };
    let err = e.set_render_options(bad).unwrap_err().to_string();
    assert!(err.contains("near"), "{err}");
    // The env keeps working with its previous settings.
    assert_eq!(e.render_options(), o);
    assert_eq!(e.sensor_rgb().unwrap().len(), 128 * 128 * 3);
}

fn decode_png(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut r = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width as usize, info.height as usize, buf)
}

#[cfg(feature = "video")]
/// Decodes an H.264 stream (Annex B access units, in order) with OpenH264's decoder.
fn decode_h264(units: &[Vec<u8>]) -> Vec<(usize, usize, Vec<u8>)> {
    use openh264::formats::YUVSource;
    let mut dec = openh264::decoder::Decoder::new().unwrap();
    let mut out = Vec::new();
    for u in units {
        if let Some(p) = dec.decode(u).unwrap() {
            let (w, h) = p.dimensions();
            let mut rgb = vec![0; w * h * 3];
            p.write_rgb8(&mut rgb);
            out.push((w, h, rgb));
        }
    }
    out
}

#[cfg(feature = "video")]
/// Peak signal-to-noise ratio of two RGB images (dB).
fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10()
}

#[cfg(feature = "video")]
#[test]
fn recorded_video_frames_decode_to_the_rendered_images() {
    use base64::Engine;
    use mjskill::record::{read_raw, video, Recorder, TOPIC_RENDER_VIDEO};
    let path = common::scratch("video.mcap");
    let mut e = env(ObsMode::State, 7);
    let mut rec = Recorder::create(&path, &e).unwrap();
    assert!(
        rec.record_frame(&[0; 3], 1, 1).is_err(),
        "video not enabled yet"
    );
    rec.enable_video("render_camera").unwrap();
    let mut frames = Vec::new();
    let a = vec![0.3f32; e.action_space().shape[0]];
    for (ep, seed) in [7u64, 8].into_iter().enumerate() {
        rec.reset(&mut e, Some(seed)).unwrap();
        frames.push(e.render().unwrap().to_vec());
        rec.record_frame(frames.last().unwrap(), 512, 512).unwrap();
        for _ in 0..2 + ep {
            rec.step(&mut e, &a).unwrap();
            frames.push(e.render().unwrap().to_vec());
            rec.record_frame(frames.last().unwrap(), 512, 512).unwrap();
        }
        rec.end_episode(false).unwrap();
    }
    assert_eq!(rec.frames(), 7);
    assert!(
        rec.record_frame(&frames[0], 256, 256).is_err(),
        "size change"
    );
    rec.finish().unwrap();

    let raw = read_raw(&path).unwrap();
    let imgs: Vec<_> = raw
        .messages
        .iter()
        .filter(|m| m.topic == TOPIC_RENDER_VIDEO)
        .collect();
    assert_eq!(imgs.len(), 7);
    let steps: Vec<u64> = raw
        .messages
        .iter()
        .filter(|m| m.topic == "/step")
        .map(|m| m.log_time)
        .collect();
    let mut units = Vec::new();
    for (k, m) in imgs.iter().enumerate() {
        assert_eq!(m.schema, "foxglove.CompressedVideo");
        assert_eq!(m.encoding, "json");
        if k > 0 && k < 3 {
            assert_eq!(m.log_time, steps[k - 1], "frame stamped with its step");
        }
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        assert_eq!(v["frame_id"], "render_camera");
        assert_eq!(v["format"], "h264");
        assert_eq!(
            v["timestamp"]["nsec"].as_u64().unwrap(),
            m.log_time % 1_000_000_000
        );
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(v["data"].as_str().unwrap())
            .unwrap();
        // Each episode starts with a keyframe carrying SPS (7) and PPS (8), as Foxglove needs.
        let types: Vec<u8> = video::nal_types(&bytes).collect();
        let first_of_episode = k == 0 || k == 3;
        assert_eq!(
            video::is_idr(&bytes),
            first_of_episode,
            "frame {k}: {types:?}"
        );
        if first_of_episode {
            assert!(types.contains(&7) && types.contains(&8), "{types:?}");
        }
        units.push(bytes);
    }
    // The frames decode (OpenH264's decoder) to the rendered images, closely.
    let decoded = decode_h264(&units);
    assert_eq!(decoded.len(), 7);
    for (k, (w, h, rgb)) in decoded.iter().enumerate() {
        assert_eq!((*w, *h), (512, 512));
        let p = psnr(rgb, &frames[k]);
        assert!(p > 35.0, "frame {k}: PSNR {p:.1} dB");
    }
    // The second episode decodes on its own, from its keyframe.
    assert_eq!(decode_h264(&units[3..]).len(), 4);
    assert_ne!(frames[0], frames[2]);
    // The episode itself still reads back.
    let r = mjskill::record::read(&path).unwrap();
    assert_eq!(r.episodes[0].steps.len(), 2);
}

#[test]
fn render_command_writes_the_human_and_sensor_frames() {
    let bin = env!("CARGO_BIN_EXE_mjskill");
    let mut e = env(ObsMode::Rgb, 4);
    let expect_human = e.render().unwrap().to_vec();
    let expect_sensor = e.sensor_rgb().unwrap().to_vec();
    for (camera, size, expect) in [
        ("render_camera", 512, expect_human),
        ("base_camera", 128, expect_sensor),
    ] {
        let out = common::scratch(&format!("{camera}.png"));
        let o = std::process::Command::new(bin)
            .args([
                "render",
                "--env",
                "PickCube-v1",
                "--seed",
                "4",
                "--camera",
                camera,
                "-o",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (w, h, rgb) = decode_png(&std::fs::read(&out).unwrap());
        assert_eq!((w, h), (size, size));
        assert_eq!(rgb, expect, "{camera}");
    }
    let o = std::process::Command::new(bin)
        .args(["render", "--camera", "top_camera", "-o"])
        .arg(common::scratch("x.png"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("top_camera") && err.contains("render_camera"),
        "{err}"
    );
}

#[cfg(feature = "video")]
#[test]
fn rollout_writes_a_frame_next_to_the_recording_and_video_on_request() {
    let out = common::scratch("roll.mcap");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(["rollout", "--episodes", "1", "--video", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let png_path = out.with_extension("png");
    assert_eq!(s["frame"], png_path.display().to_string());
    assert_eq!(s["video_frames"], 51, "reset + 50 steps");
    let (w, h, rgb) = decode_png(&std::fs::read(&png_path).unwrap());
    assert_eq!((w, h), (512, 512));
    // The solver lifted the cube to the goal: both red and green are in view.
    let px = |f: fn([u8; 3]) -> bool| rgb.chunks(3).filter(|c| f([c[0], c[1], c[2]])).count();
    assert!(
        px(is_red) > 20 && px(is_green) > 5,
        "{} {}",
        px(is_red),
        px(is_green)
    );
    let raw = mjskill::record::read_raw(&out).unwrap();
    let n = raw
        .messages
        .iter()
        .filter(|m| m.topic == mjskill::record::TOPIC_RENDER_VIDEO)
        .count();
    assert_eq!(n, 51);
}

#[test]
fn visual_envs_render_on_vec_env_worker_threads() {
    // Envs (and their GL contexts) are built on this thread and stepped on a worker thread.
    let config = EnvConfig {
        obs_mode: ObsMode::Rgb,
        ..Default::default()
    };
    let mut v = mjskill::VecEnv::new("PickCube-v1", config, 2, 2).unwrap();
    v.reset(Some(5));
    let dim = v.single_action_space().shape[0];
    let acts: Vec<f32> = (0..2 * dim).map(|i| (i as f32 * 0.4).sin()).collect();
    for _ in 0..3 {
        v.step(&acts).unwrap();
    }
    for i in 0..2 {
        let mut e = env(ObsMode::Rgb, 5 + i as u64);
        for _ in 0..3 {
            e.step(&acts[i * dim..(i + 1) * dim]).unwrap();
        }
        assert_eq!(v.obs_of(i).unwrap(), e.obs(), "env {i}");
    }
}

fn fetch_env(mode: ObsMode, seed: u64) -> Env {
    let mut e = make(
        "PickCube-v1",
        EnvConfig {
            robot: Some("fetch".into()),
            obs_mode: mode,
            ..Default::default()
        },
    )
    .unwrap();
    e.reset(Some(seed));
    e
}

/// MuJoCo camera pose (position, rotation with columns right, up, backward).
fn camera_pose(env: &Env, name: &str) -> (Vector3<f64>, Matrix3<f64>) {
    let id = env.model().require_id(ObjType::Camera, name).unwrap();
    let d = env.data();
    let p = &d.cam_xpos()[3 * id..3 * id + 3];
    (
        Vector3::new(p[0], p[1], p[2]),
        Matrix3::from_row_slice(&d.cam_xmat()[9 * id..9 * id + 9]),
    )
}

#[test]
fn fetch_cameras_sit_on_their_links_and_look_along_the_link_x_axis() {
    let mut e = fetch_env(ObsMode::Rgb, 0);
    // Move the head and arm so that the link frames are not axis-aligned.
    let a: Vec<f32> = (0..e.action_space().shape[0])
        .map(|i| 0.3 * (i as f32 + 1.0).sin())
        .collect();
    for _ in 0..3 {
        e.step(&a).unwrap();
    }
    assert_eq!(
        e.sensor_names(),
        vec!["base_camera", "fetch_head", "fetch_hand"]
    );
    for (cam, link, offset) in [
        ("fetch_head", "head_camera_link", Vector3::zeros()),
        ("fetch_hand", "gripper_link", Vector3::new(-0.1, 0.0, 0.1)),
    ] {
        let (lp, lr) = body(&e, link);
        let (cp, cr) = camera_pose(&e, cam);
        assert!(
            (cp - (lp + lr * offset)).norm() < 1e-9,
            "{cam}: {cp} vs link {lp}"
        );
        // SAPIEN's camera frame (forward, left, up) = the link's (x, y, z): MuJoCo's camera
        // looks along its −z with +y up and +x right.
        let (fwd, left, up) = (lr.column(0), lr.column(1), lr.column(2));
        assert!(
            (-cr.column(2) - fwd).norm() < 1e-9,
            "{cam} looks along the link's +x"
        );
        assert!(
            (cr.column(1) - up).norm() < 1e-9,
            "{cam}: up is the link's +z"
        );
        assert!(
            (cr.column(0) + left).norm() < 1e-9,
            "{cam}: right is the link's −y"
        );
        assert!(lr.column(0).z.abs() < 0.999, "the link frame is tilted");
        let id = e.model().require_id(ObjType::Camera, cam).unwrap();
        assert!((e.model().cam_fovy()[id] - 2f64.to_degrees()).abs() < 1e-9);
    }
    // The head is turned away from the world axes by the body action.
    let (_, head) = body(&e, "head_camera_link");
    assert!((head.column(0) - Vector3::x()).norm() > 0.01);
}

#[test]
fn fetch_camera_images_exist_differ_and_are_deterministic() {
    let mut e = fetch_env(ObsMode::Rgb, 1);
    let imgs: Vec<Vec<u8>> = ["base_camera", "fetch_head", "fetch_hand"]
        .iter()
        .map(|n| {
            let img = e.image(n).unwrap();
            assert_eq!((img.name, img.width, img.height), (*n, 128, 128));
            assert!(img.depth.is_none());
            let rgb = img.rgb.unwrap();
            assert_eq!(rgb.len(), 128 * 128 * 3);
            rgb.to_vec()
        })
        .collect();
    assert_ne!(imgs[0], imgs[1]);
    assert_ne!(imgs[0], imgs[2]);
    assert_ne!(imgs[1], imgs[2]);
    // The hand camera looks down at the table from behind the gripper and sees the cube.
    let reds = imgs[2]
        .chunks(3)
        .filter(|c| is_red([c[0], c[1], c[2]]))
        .count();
    assert!(reds > 0, "the cube is in the hand camera's view");
    // Same state ⇒ same images; a step changes the hand view.
    let s = e.get_state();
    let a = vec![0.5f32; e.action_space().shape[0]];
    e.step(&a).unwrap();
    assert_ne!(e.image("fetch_hand").unwrap().rgb.unwrap(), &imgs[2][..]);
    e.set_state(&s).unwrap();
    for (n, img) in ["base_camera", "fetch_head", "fetch_hand"]
        .iter()
        .zip(&imgs)
    {
        assert_eq!(e.image(n).unwrap().rgb.unwrap(), &img[..], "{n}");
    }
    let f = fetch_env(ObsMode::Rgb, 1);
    assert_eq!(f.image("fetch_head").unwrap().rgb.unwrap(), &imgs[1][..]);
    // Depth modes give the robot cameras depth too; state modes and Panda have none.
    let d = fetch_env(ObsMode::Depth, 1);
    let hd = d.image("fetch_hand").unwrap();
    assert!(hd.rgb.is_none());
    assert!(hd
        .depth
        .unwrap()
        .iter()
        .all(|z| z.is_finite() && *z >= 0.01 && *z <= 100.0));
    assert!(fetch_env(ObsMode::State, 1).image("fetch_head").is_none());
    let p = env(ObsMode::Rgb, 1);
    assert!(p.image("fetch_head").is_none());
    assert_eq!(p.sensor_names(), vec!["base_camera"]);
}
