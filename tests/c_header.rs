//! src/io/mrsmap_wire.h, the C and C++ definitions of the wire messages and services,
//! against the Rust ones (`io::wire`, `io::ipc`): a program compiled with the system's
//! C compiler (and C++ compiler) prints every size, alignment, field offset and field
//! size, every type name and every service setting of the header, and each must equal
//! what the Rust side has. The fields must tile each struct (no padding, none left out).
//!
//! The C compiler is the one Rust links with (`$CC`, else `cc`), so it is on every
//! machine that runs these tests. A C++ compiler (`$CXX`, else `c++`) may be missing:
//! then the C++ check says so and passes, unless `MRSMAP_REQUIRE_CXX=1` (as `.ci/run`
//! sets), which makes it fail.

mod common;

use common::*;
use mrsmap::io::ipc::{self, DETECTION_QOS, FRAME_QOS, FrameSize, PubSubQos};
use mrsmap::io::wire::{
    self, FrameHeader, ObjectDetection, ObjectPose, RgbdFrameQvga, RgbdFrameVga, detection_mode, status,
};
use std::mem::{align_of, offset_of, size_of};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A message type as Rust lays it out.
struct Layout {
    /// The C type's name.
    c_name: &'static str,
    /// The C macro holding its iceoryx2 type name.
    type_name_macro: &'static str,
    type_name: &'static str,
    size: usize,
    align: usize,
    /// Field name and offset, in declaration order.
    fields: Vec<(&'static str, usize)>,
}

macro_rules! layout {
    ($rust:ty, $c:literal, $macro:literal, [$($field:ident),* $(,)?]) => {
        Layout {
            c_name: $c,
            type_name_macro: $macro,
            type_name: wire::type_name_of::<$rust>(),
            size: size_of::<$rust>(),
            align: align_of::<$rust>(),
            fields: vec![$((stringify!($field), offset_of!($rust, $field))),*],
        }
    };
}

fn layouts() -> Vec<Layout> {
    vec![
        layout!(
            FrameHeader,
            "MrsmapFrameHeader",
            "MRSMAP_FRAME_HEADER_TYPE_NAME",
            [
                layout_version,
                width,
                height,
                reserved,
                capture_stamp_ns,
                send_stamp_ns,
                sequence,
                fx,
                fy,
                cx,
                cy,
                distortion,
                depth_scale_m,
            ]
        ),
        layout!(RgbdFrameVga, "MrsmapRgbdFrameVga", "MRSMAP_RGBD_FRAME_VGA_TYPE_NAME", [header, rgb, depth]),
        layout!(RgbdFrameQvga, "MrsmapRgbdFrameQvga", "MRSMAP_RGBD_FRAME_QVGA_TYPE_NAME", [header, rgb, depth]),
        layout!(
            ObjectPose,
            "MrsmapObjectPose",
            "MRSMAP_OBJECT_POSE_TYPE_NAME",
            [
                layout_version,
                object_id,
                frame_stamp_ns,
                frame_sequence,
                frame_send_stamp_ns,
                publish_stamp_ns,
                translation_m,
                rotation_xyzw,
                covariance,
                quality,
                status,
                bad_frames,
                associations,
                iterations,
                build_ms,
                register_ms,
                total_ms,
                free_space,
                name,
            ]
        ),
        layout!(
            ObjectDetection,
            "MrsmapObjectDetection",
            "MRSMAP_OBJECT_DETECTION_TYPE_NAME",
            [layout_version, mode, frame_stamp_ns, send_stamp_ns, translation_m, rotation_xyzw, name,]
        ),
    ]
}

/// The header's numeric constants and the values the Rust side has for them.
fn numbers() -> Vec<(String, u64)> {
    let qos = |prefix: &str, q: PubSubQos| {
        let name = |field: &str| format!("MRSMAP_{prefix}_{field}");
        vec![
            (name("SAFE_OVERFLOW"), u64::from(q.safe_overflow)),
            (name("SUBSCRIBER_MAX_BUFFER_SIZE"), q.subscriber_max_buffer_size as u64),
            (name("SUBSCRIBER_MAX_BORROWED_SAMPLES"), q.subscriber_max_borrowed_samples as u64),
            (name("HISTORY_SIZE"), q.history_size as u64),
            (name("MAX_PUBLISHERS"), q.max_publishers as u64),
            (name("MAX_SUBSCRIBERS"), q.max_subscribers as u64),
        ]
    };
    let mut all: Vec<(String, u64)> = [
        ("MRSMAP_LAYOUT_VERSION", u64::from(wire::LAYOUT_VERSION)),
        ("MRSMAP_EVENT_MAX_NOTIFIERS", ipc::EVENT_MAX_NOTIFIERS as u64),
        ("MRSMAP_EVENT_MAX_LISTENERS", ipc::EVENT_MAX_LISTENERS as u64),
        ("MRSMAP_POSES_MAX_READERS", ipc::POSES_MAX_READERS as u64),
        ("MRSMAP_MAX_OBJECTS", u64::from(ipc::MAX_OBJECTS)),
        ("MRSMAP_STATUS_TRACKING", u64::from(status::TRACKING)),
        ("MRSMAP_STATUS_LOST", u64::from(status::LOST)),
        ("MRSMAP_STATUS_INITIALISING", u64::from(status::INITIALISING)),
        ("MRSMAP_STATUS_INVALID_FRAME", u64::from(status::INVALID_FRAME)),
        ("MRSMAP_DETECTION_WHEN_NOT_TRACKING", u64::from(detection_mode::WHEN_NOT_TRACKING)),
        ("MRSMAP_DETECTION_ALWAYS", u64::from(detection_mode::ALWAYS)),
    ]
    .into_iter()
    .map(|(name, v)| (name.to_string(), v))
    .collect();
    all.extend(qos("FRAME", FRAME_QOS));
    all.extend(qos("DETECTION", DETECTION_QOS));
    all
}

/// The header's string constants and the Rust side's.
fn strings() -> Vec<(&'static str, &'static str)> {
    vec![
        ("MRSMAP_DEFAULT_CAMERA_SERVICE", ipc::DEFAULT_CAMERA_SERVICE),
        ("MRSMAP_VGA_SUFFIX", FrameSize::Vga.suffix()),
        ("MRSMAP_QVGA_SUFFIX", FrameSize::Qvga.suffix()),
        ("MRSMAP_POSES_SERVICE", ipc::POSES_SERVICE),
        ("MRSMAP_DETECTIONS_SERVICE", ipc::DETECTIONS_SERVICE),
    ]
}

/// A program, valid C11 and C++17, that prints what the header says: one line per
/// struct (size, alignment, type name), per field (offset, size), per constant.
fn program() -> String {
    let mut body = String::new();
    for l in layouts() {
        let t = l.c_name;
        body += &format!(
            "    printf(\"{t} %zu %zu %s\\n\", sizeof({t}), (size_t)ALIGN({t}), TYPE_NAME({t}, {}));\n",
            l.type_name_macro
        );
        for (f, _) in &l.fields {
            body += &format!("    printf(\"{t}.{f} %zu %zu\\n\", offsetof({t}, {f}), sizeof((({t}*)0)->{f}));\n");
        }
    }
    for (name, _) in numbers() {
        body += &format!("    printf(\"{name} %llu\\n\", (unsigned long long)({name}));\n");
    }
    for (name, _) in strings() {
        body += &format!("    printf(\"{name} %s\\n\", {name});\n");
    }
    format!(
        "#include \"mrsmap_wire.h\"\n#include <stdio.h>\n\
         #ifdef __cplusplus\n#define ALIGN(T) alignof(T)\n#define TYPE_NAME(T, MACRO) T::IOX2_TYPE_NAME\n\
         #else\n#define ALIGN(T) _Alignof(T)\n#define TYPE_NAME(T, MACRO) MACRO\n#endif\n\
         int main(void) {{\n{body}    return 0;\n}}\n"
    )
}

/// What the program must print: the Rust side's values. (The field sizes come from the
/// C side; [`check_tiling`] checks them.)
fn expected_without_field_sizes() -> Vec<String> {
    let mut lines = Vec::new();
    for l in layouts() {
        lines.push(format!("{} {} {} {}", l.c_name, l.size, l.align, l.type_name));
        lines.extend(l.fields.iter().map(|(f, offset)| format!("{}.{f} {offset}", l.c_name)));
    }
    lines.extend(numbers().into_iter().map(|(name, v)| format!("{name} {v}")));
    lines.extend(strings().into_iter().map(|(name, v)| format!("{name} {v}")));
    lines
}

/// Each struct's fields, by the offsets and sizes the compiler printed, follow one
/// another without a gap and end at the struct's size: no padding, no field unlisted.
fn check_tiling(output: &[&str], compiler: &str) {
    for l in layouts() {
        let mut end = 0;
        for (f, offset) in &l.fields {
            let key = format!("{}.{f} ", l.c_name);
            let line = output.iter().find(|x| x.starts_with(&key)).unwrap_or_else(|| panic!("{compiler}: no {key}"));
            let size: usize = line.rsplit(' ').next().and_then(|s| s.parse().ok()).expect("field size");
            assert_eq!(*offset, end, "{compiler}: {}.{f} does not follow the field before it", l.c_name);
            end = offset + size;
        }
        assert_eq!(end, l.size, "{compiler}: the fields of {} do not fill it", l.c_name);
    }
}

/// Compiles the program with `compiler` and `flags`, runs it, checks its output. `None`
/// if the compiler cannot be started.
fn compile_and_check(compiler: &str, flags: &[&str], source_name: &str) -> Option<()> {
    let dir = temp_dir(&format!("c-header-{source_name}"));
    let source = dir.join(source_name);
    std::fs::write(&source, program()).expect("write the program");
    let exe: PathBuf = dir.join("layout");
    let include: &Path = &root().join("src/io");
    let out =
        Command::new(compiler).args(flags).arg("-I").arg(include).arg(&source).arg("-o").arg(&exe).output().ok()?;
    assert!(out.status.success(), "{compiler} rejected the header:\n{}", String::from_utf8_lossy(&out.stderr));
    let run = Command::new(&exe).output().expect("run the layout program");
    assert!(run.status.success());
    let text = String::from_utf8(run.stdout).expect("UTF-8");
    let lines: Vec<&str> = text.lines().collect();
    // Compare without the field sizes (the last number of each field line).
    let printed: Vec<String> = lines
        .iter()
        .map(|line| match line.split_once(' ') {
            Some((key, rest)) if key.contains('.') => format!("{key} {}", rest.split(' ').next().unwrap_or("")),
            _ => line.to_string(),
        })
        .collect();
    let expected = expected_without_field_sizes();
    for (got, want) in printed.iter().zip(&expected) {
        assert_eq!(got, want, "{compiler}: the header disagrees with the Rust definitions");
    }
    assert_eq!(printed.len(), expected.len(), "{compiler}: lines printed");
    check_tiling(&lines, compiler);
    Some(())
}

fn from_env(var: &str, default: &str) -> String {
    std::env::var(var).ok().filter(|v| !v.is_empty()).unwrap_or_else(|| default.to_string())
}

#[test]
fn the_c_header_matches_the_rust_wire_types() {
    let cc = from_env("CC", "cc");
    let flags = ["-std=c11", "-Wall", "-Wextra", "-Werror", "-pedantic"];
    compile_and_check(&cc, &flags, "layout.c").unwrap_or_else(|| panic!("no C compiler `{cc}` (set CC)"));
}

#[test]
fn the_header_compiles_as_cpp_with_the_iceoryx2_type_names() {
    let cxx = from_env("CXX", "c++");
    let flags = ["-x", "c++", "-std=c++17", "-Wall", "-Wextra", "-Werror", "-pedantic"];
    if compile_and_check(&cxx, &flags, "layout.cpp").is_none() {
        assert!(
            std::env::var("MRSMAP_REQUIRE_CXX").as_deref() != Ok("1"),
            "no C++ compiler `{cxx}` and MRSMAP_REQUIRE_CXX=1"
        );
        eprintln!("no C++ compiler `{cxx}`: the header's C++ part was not checked (set CXX)");
    }
}
