//! Generates the MuJoCo 2.2 bindings with bindgen from the system headers.
//!
//! Debian ships the headers in `libmujoco-dev` (as `/usr/include/mujoco/mujoco.h`) and no
//! pkg-config file, so the library is linked by name. bindgen needs libclang (`libclang-dev`).
//!
//! `MUJOCO_INCLUDE_DIR` and `MUJOCO_LIB_DIR` point the build at another MuJoCo 2.2.2: the
//! manylinux wheel builds against one compiled for glibc 2.28 (python/build_mujoco.sh).
use std::env;
use std::path::PathBuf;

const INSTALL_HINT: &str =
    "install the Debian packages: apt-get install -y libmujoco-dev libclang-dev";

fn fail(msg: &str) -> ! {
    // One clear line, then stop the build.
    eprintln!("error: mujoco-sys: {msg}; {INSTALL_HINT}");
    println!("cargo:warning=mujoco-sys: {msg}; {INSTALL_HINT}");
    std::process::exit(1);
}

fn main() {
    println!("cargo:rerun-if-changed=wrapper.h");
    println!("cargo:rerun-if-env-changed=MUJOCO_INCLUDE_DIR");
    let include_dir = env::var("MUJOCO_INCLUDE_DIR").unwrap_or_else(|_| "/usr/include".to_string());
    let header = PathBuf::from(&include_dir).join("mujoco/mujoco.h");
    if !header.exists() {
        fail(&format!("MuJoCo headers not found at {}", header.display()));
    }
    println!("cargo:rerun-if-changed={}", header.display());
    println!("cargo:rerun-if-env-changed=MUJOCO_LIB_DIR");
    if let Ok(lib_dir) = env::var("MUJOCO_LIB_DIR") {
        if !PathBuf::from(&lib_dir).join("libmujoco.so").exists() {
            fail(&format!("MUJOCO_LIB_DIR={lib_dir} has no libmujoco.so"));
        }
        println!("cargo:rustc-link-search=native={lib_dir}");
    }
    println!("cargo:rustc-link-lib=dylib=mujoco");

    // bindgen panics when libclang cannot be loaded; turn that into the one-line message.
    let result = std::panic::catch_unwind(|| {
        bindgen::Builder::default()
            .header("wrapper.h")
            .clang_arg(format!("-I{include_dir}"))
            .allowlist_function("mj.*")
            .allowlist_type("mj.*")
            .allowlist_var("mj.*")
            .derive_default(true)
            .layout_tests(true)
            .generate()
    });
    let bindings = match result {
        Ok(Ok(b)) => b,
        Ok(Err(e)) => fail(&format!("bindgen failed on the MuJoCo headers ({e})")),
        Err(_) => fail("libclang could not be loaded by bindgen"),
    };
    let out = PathBuf::from(env::var("OUT_DIR").expect("OUT_DIR is set by cargo"));
    if let Err(e) = bindings.write_to_file(out.join("bindings.rs")) {
        fail(&format!("cannot write bindings ({e})"));
    }
}
