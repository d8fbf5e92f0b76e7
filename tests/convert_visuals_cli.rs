//! `mjskill-meshes convert-visuals` under hostile input: glTF node graphs with cycles or shared
//! children, PNG textures declaring (or decompressing to) huge sizes, non-finite vertices,
//! huge polygons and URDFs with duplicate link names. Every file is crafted here; each case
//! ends in an error naming the file and the limit, or in a correct conversion.
#![cfg(feature = "mesh-tools")]

mod common;
use std::path::Path;
use std::process::{Command, Output};

use base64::Engine as _;

fn convert(args: &[&str], out_dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mjskill-meshes"))
        .arg("convert-visuals")
        .args(args)
        .arg("--out-dir")
        .arg(out_dir)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// Asserts that `o` failed with a message containing every one of `needles`.
fn assert_error(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert!(
        !o.status.success(),
        "expected an error, got success: {}",
        stdout(o)
    );
    assert_eq!(o.status.code(), Some(2), "not a clean error exit: {e}");
    for n in needles {
        assert!(e.contains(n), "{n:?} missing from: {e}");
    }
}

/// A `.gltf` (JSON, buffer embedded as a data URI) with one triangle mesh and `nodes` (each a
/// JSON object; `"mesh": 0` draws the triangle); the scene's root is node 0.
fn gltf(nodes: &[String]) -> String {
    let mut buf = Vec::new();
    for v in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    let data = base64::engine::general_purpose::STANDARD.encode(&buf);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                       "min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{data}"}}]}}"#,
        nodes.join(",")
    )
}

#[test]
fn gltf_node_cycle_is_refused_naming_the_node() {
    let d = common::scratch_dir("cycle");
    // Node 0 draws the triangle and is its own child; node 1 -> 2 -> 1 is a longer cycle.
    for (k, nodes) in [
        vec![r#"{"name":"loop","mesh":0,"children":[0]}"#.to_string()],
        vec![
            r#"{"mesh":0,"children":[1]}"#.to_string(),
            r#"{"name":"a","mesh":0,"children":[2]}"#.to_string(),
            r#"{"name":"b","children":[1]}"#.to_string(),
        ],
    ]
    .into_iter()
    .enumerate()
    {
        let f = d.join(format!("cycle{k}.gltf"));
        std::fs::write(&f, gltf(&nodes)).unwrap();
        let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out"));
        let node = if k == 0 {
            "node 0 (\"loop\")"
        } else {
            "node 1 (\"a\")"
        };
        assert_error(&o, &[f.to_str().unwrap(), node, "cycle"]);
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn gltf_shared_children_are_bounded() {
    let d = common::scratch_dir("dag");
    // A Fibonacci-shaped graph: node i has the children i+1 and i+2, and nodes 24 and 25 draw
    // the triangle, so the root expands to about 240,000 instances from 26 nodes (40 nodes
    // would make 3·10⁸).
    let mut nodes: Vec<String> = (0..24)
        .map(|i| {
            format!(
                r#"{{"children":[{},{}],"translation":[0,0,{i}]}}"#,
                i + 1,
                i + 2
            )
        })
        .collect();
    nodes.push(r#"{"mesh":0}"#.into());
    nodes.push(r#"{"mesh":0,"translation":[1,0,0]}"#.into());
    let f = d.join("dag.gltf");
    std::fs::write(&f, gltf(&nodes)).unwrap();
    let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out"));
    assert_error(
        &o,
        &[f.to_str().unwrap(), "more than 100000 node instances"],
    );
    std::fs::remove_dir_all(&d).ok();
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
}

/// A PNG that declares `w` x `h` RGBA pixels and holds no image data.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn png_declaring_a_huge_size_is_refused_before_decoding() {
    let d = common::scratch_dir("pnghuge");
    // 100,000 x 100,000 RGBA would be a 40 GB allocation.
    let f = d.join("huge.png");
    std::fs::write(&f, png_header_only(100_000, 100_000)).unwrap();
    let o = convert(&["--texture", f.to_str().unwrap()], &d.join("out"));
    assert_error(
        &o,
        &[
            f.to_str().unwrap(),
            "100000 x 100000",
            "at most 16384 pixels a side and 67108864 pixels in all",
        ],
    );
    // Within the side limit, over the pixel limit (8193 x 8193).
    std::fs::write(&f, png_header_only(8193, 8193)).unwrap();
    let o = convert(&["--texture", f.to_str().unwrap()], &d.join("out"));
    assert_error(&o, &[f.to_str().unwrap(), "8193 x 8193", "67108864 pixels"]);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn png_bomb_is_refused_by_its_declared_size() {
    let d = common::scratch_dir("pngbomb");
    // 9000 x 9000 grey zeros: 81 MB of pixels in a file of about 80 KB, more pixels than
    // the limit allows.
    let f = d.join("bomb.png");
    let (w, h) = (9000u32, 9000u32);
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut wr = enc.write_header().unwrap();
        wr.write_image_data(&vec![0u8; (w * h) as usize]).unwrap();
    }
    assert!(bytes.len() < 2_000_000, "{}", bytes.len());
    std::fs::write(&f, &bytes).unwrap();
    let o = convert(&["--texture", f.to_str().unwrap()], &d.join("out"));
    assert_error(&o, &[f.to_str().unwrap(), "9000 x 9000", "67108864 pixels"]);
    // A texture within the limits still converts.
    let small = d.join("small.png");
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, 64, 32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().unwrap();
        wr.write_image_data(&[200u8; 64 * 32 * 3]).unwrap();
    }
    std::fs::write(&small, &bytes).unwrap();
    let o = convert(
        &["--texture", small.to_str().unwrap(), "--texture-size", "16"],
        &d.join("out"),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("(16x8)"), "{}", stdout(&o));
    std::fs::remove_dir_all(&d).ok();
}

/// A COLLADA file with one tetrahedron whose positions and normals are given.
fn dae(positions: &str, normals: &str) -> String {
    format!(
        r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <library_geometries><geometry id="g"><mesh>
    <source id="pos"><float_array id="pa" count="12">{positions}</float_array>
      <technique_common><accessor source="#pa" count="4" stride="3"/></technique_common></source>
    <source id="nrm"><float_array id="na" count="3">{normals}</float_array>
      <technique_common><accessor source="#na" count="1" stride="3"/></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#pos"/></vertices>
    <triangles count="4"><input semantic="VERTEX" source="#v" offset="0"/>
      <input semantic="NORMAL" source="#nrm" offset="1"/>
      <p>0 0 2 0 1 0  0 0 1 0 3 0  0 0 3 0 2 0  1 0 2 0 3 0</p></triangles>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n">
    <instance_geometry url="#g"/></node></visual_scene></library_visual_scenes>
</COLLADA>"##
    )
}

#[test]
fn collada_with_non_finite_vertices_is_refused() {
    let d = common::scratch_dir("nan");
    let good = "0 0 0 1 0 0 0 1 0 0 0 1";
    let f = d.join("tet.dae");
    // The well-formed file converts.
    std::fs::write(&f, dae(good, "0 0 1")).unwrap();
    let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out"));
    assert!(o.status.success(), "{}", stderr(&o));
    let obj = std::fs::read_to_string(d.join("out/visual_0.obj")).unwrap();
    assert!(!obj.contains("NaN") && !obj.contains("inf"), "{obj}");
    for (positions, normals, what) in [
        (
            "NaN NaN NaN 1 0 0 0 1 0 0 0 1",
            "0 0 1",
            "the position [NaN, NaN, NaN]",
        ),
        (
            "0 0 0 inf 0 0 0 1 0 0 0 1",
            "0 0 1",
            "vertex 2 has the position [",
        ),
        (
            "0 0 0 2e6 0 0 0 1 0 0 0 1",
            "0 0 1",
            "the position [2000000.0, 0.0, 0.0]",
        ),
        (good, "NaN 0 1", "the normal [NaN, NaN, NaN]"),
    ] {
        std::fs::write(&f, dae(positions, normals)).unwrap();
        let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out2"));
        assert_error(&o, &[f.to_str().unwrap(), what, "must be finite"]);
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_polygon_with_a_million_corners_converts() {
    // One OBJ face with 1,000,000 corners over the 8 corners of a cube: the fan makes a
    // million triangles, all but a few degenerate or repeated. Before they were dropped up
    // front, normals compared every triangle at a corner with every other one there (a 200,000
    // corner face took over a minute; this one would take half an hour).
    let d = common::scratch_dir("polygon");
    let mut text = String::new();
    for i in 0..8 {
        text.push_str(&format!("v {} {} {}\n", i & 1, (i >> 1) & 1, (i >> 2) & 1));
    }
    text.push('f');
    // Corners cycle 1 2 4 3 (the z = 0 square) and 5 6 8 7 (z = 1) in turn.
    let cycle = [1, 2, 4, 3, 5, 6, 8, 7];
    for k in 0..1_000_000 {
        text.push_str(&format!(" {}", cycle[k % 8]));
    }
    text.push('\n');
    let f = d.join("polygon.obj");
    std::fs::write(&f, text).unwrap();
    let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out"));
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stdout(&o);
    assert!(log.contains("999998 -> "), "{log}");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_cone_over_a_polygon_with_200000_distinct_corners_converts() {
    // A cone: its base one OBJ face of 200,000 distinct corners, its side 200,000 triangles
    // meeting at the apex. Both the base's fan centre and the apex are shared by 200,000
    // triangles, and meshoptimizer's vertex classification and vertex cache ordering took
    // time quadratic in that (minutes) before such vertices were split.
    let d = common::scratch_dir("cone");
    let n = 200_000;
    let mut text = String::from("v 0 0 0.5\n");
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        text.push_str(&format!("v {:.7} {:.7} 0\n", a.cos(), a.sin()));
    }
    for k in 0..n {
        text.push_str(&format!("f 1 {} {}\n", k + 2, (k + 1) % n + 2));
    }
    text.push('f');
    for k in (0..n).rev() {
        text.push_str(&format!(" {}", k + 2));
    }
    text.push('\n');
    let f = d.join("cone.obj");
    std::fs::write(&f, text).unwrap();
    let o = convert(&["--mesh", f.to_str().unwrap()], &d.join("out"));
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stdout(&o);
    assert!(log.contains("1 parts, 399998 -> "), "{log}");
    let obj = std::fs::read_to_string(d.join("out/visual_0.obj")).unwrap();
    assert!(obj.lines().filter(|l| l.starts_with("f ")).count() > 100);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn duplicate_link_names_in_a_urdf_are_refused() {
    let d = common::scratch_dir("duplinks");
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    std::fs::write(d.join("a.obj"), obj).unwrap();
    std::fs::write(d.join("b.obj"), obj).unwrap();
    let urdf = d.join("robot.urdf");
    std::fs::write(
        &urdf,
        r#"<robot name="r">
  <link name="base"><visual><geometry><mesh filename="a.obj"/></geometry></visual></link>
  <link name="base"><visual><geometry><mesh filename="b.obj" scale="2 2 2"/></geometry></visual></link>
</robot>"#,
    )
    .unwrap();
    let o = convert(&["--urdf", urdf.to_str().unwrap()], &d.join("out"));
    assert_error(
        &o,
        &[urdf.to_str().unwrap(), "link \"base\" is defined twice"],
    );
    assert!(!d.join("out/base_0_0.obj").exists());
    std::fs::remove_dir_all(&d).ok();
}
