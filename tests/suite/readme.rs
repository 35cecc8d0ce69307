//! README.md's commands run as written. Every `cargo run --release -- …` line of its bash blocks
//! runs, in README order, in one scratch directory (so each command finds the files the ones
//! before it wrote; `examples/` and `../shared` are reachable as from the repository root), with
//! this build's binary in place of `cargo run --release --`, and must exit 0. The service block is
//! an excerpt of `scripts/api_walkthrough.sh`, line for line, and that script runs against a
//! server. The one long command (the Algorithm 5.1 study) runs with
//! `cargo test --release --test suite readme:: -- --ignored` (every command, 27 s in release). A command
//! that fails on purpose says so on its line (`# exits 1: …`), and must exit with that status.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A command of a bash block and its README line.
struct Cmd {
    line: usize,
    text: String,
}

fn readme() -> String {
    std::fs::read_to_string(Path::new(ROOT).join("README.md")).unwrap()
}

/// The bash blocks (indented ones too), each as (first line number, lines).
fn bash_blocks(text: &str) -> Vec<(usize, Vec<String>)> {
    let mut blocks = Vec::new();
    let mut current: Option<(usize, Vec<String>)> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        match &mut current {
            None if t.starts_with("```bash") => current = Some((i + 2, Vec::new())),
            Some(_) if t.starts_with("```") => blocks.push(current.take().unwrap()),
            Some((_, lines)) => lines.push(t.to_string()),
            None => {}
        }
    }
    blocks
}

/// The `cargo run --release -- …` commands, continuation lines joined.
fn cli_commands(text: &str) -> Vec<Cmd> {
    let mut out = Vec::new();
    for (first, lines) in bash_blocks(text) {
        let mut i = 0;
        while i < lines.len() {
            let (line, mut cmd) = (first + i, lines[i].clone());
            while cmd.ends_with('\\') && i + 1 < lines.len() {
                cmd.pop();
                i += 1;
                cmd.push(' ');
                cmd.push_str(lines[i].trim());
            }
            i += 1;
            if cmd.starts_with("cargo run --release -- ") {
                out.push(Cmd { line, text: cmd });
            }
        }
    }
    out
}

/// The one long command (the Algorithm 5.1 study: 2,430 DETMAX selections and identifications,
/// 19 s in release, about a minute unoptimised): run by the ignored test only.
fn slow(cmd: &str) -> bool {
    cmd.contains("-- study ")
}

/// The scratch directory: `work/` with `examples` linked in, `shared` beside it.
fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("robocal-readme-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let work = dir.join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::os::unix::fs::symlink(Path::new(ROOT).join("examples"), work.join("examples")).unwrap();
    std::os::unix::fs::symlink(Path::new(ROOT).join("../shared"), dir.join("shared")).unwrap();
    work
}

/// The three-reflector import reads a user's files; write files of the documented format from the
/// simulated reflector plate (`plate.json`, an earlier README command): one joints line per pose,
/// one positions file per reflector, line-aligned, `nan nan nan` where a reflector was not read.
fn write_reflector_files(work: &Path) {
    let plate: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(work.join("plate.json")).expect("plate.json")).unwrap();
    let sessions = plate["sessions"].as_array().unwrap();
    let tracker: Vec<&serde_json::Value> =
        sessions.iter().filter(|s| s["name"].as_str().unwrap().starts_with("tracker-n")).collect();
    let key = |m: &serde_json::Value| m["joints_deg"].to_string();
    let mut poses: Vec<String> = Vec::new();
    for s in &tracker {
        for m in s["measurements"].as_array().unwrap() {
            if !poses.contains(&key(m)) {
                poses.push(key(m));
            }
        }
    }
    let line = |v: &serde_json::Value| {
        v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap().to_string()).collect::<Vec<_>>().join(" ")
    };
    let joints: String = poses.iter().map(|p| line(&serde_json::from_str(p).unwrap()) + "\n").collect();
    std::fs::write(work.join("joints.txt"), joints).unwrap();
    for (k, s) in tracker.iter().enumerate() {
        let ms = s["measurements"].as_array().unwrap();
        let text: String = poses
            .iter()
            .map(|p| match ms.iter().find(|m| &key(m) == p) {
                Some(m) => line(&m["position_mm"]) + "\n",
                None => "nan nan nan\n".to_string(),
            })
            .collect();
        std::fs::write(work.join(format!("r{}.txt", k + 1)), text).unwrap();
    }
}

fn run_cli_commands(include_slow: bool) {
    let work = scratch(if include_slow { "all" } else { "fast" });
    let bin = env!("CARGO_BIN_EXE_robocal");
    let mut ran = 0;
    for c in cli_commands(&readme()) {
        let sub = c.text["cargo run --release -- ".len()..].split_whitespace().next().unwrap_or_default();
        if sub == "serve" {
            continue; // long-running: tests/suite/server_process.rs and the walkthrough below start it
        }
        if slow(&c.text) && !include_slow {
            continue;
        }
        if c.text.contains("import three-reflector") {
            write_reflector_files(&work);
        }
        let script = c.text.replacen("cargo run --release --", "\"$ROBOCAL\"", 1);
        let started = Instant::now();
        let out = Command::new("bash").args(["-c", &script]).env("ROBOCAL", bin).current_dir(&work).output().unwrap();
        // A command that fails on purpose says so: `# exits N`.
        let expected =
            c.text.split("# exits ").nth(1).and_then(|r| r.split(':').next()?.trim().parse().ok()).unwrap_or(0);
        assert!(
            out.status.code() == Some(expected),
            "README.md line {}: `{}` exited {:?}\nstdout: {}\nstderr: {}",
            c.line,
            c.text,
            out.status.code(),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        eprintln!("README line {} ran in {:.1} s: {}", c.line, started.elapsed().as_secs_f64(), c.text);
        ran += 1;
    }
    assert!(ran >= 20, "only {ran} README commands found");
}

#[test]
fn the_readme_commands_run_as_written() {
    run_cli_commands(false);
}

#[test]
#[ignore = "the Algorithm 5.1 study as well: 19 s in release, about a minute unoptimised"]
fn every_readme_command_runs_as_written() {
    run_cli_commands(true);
}

/// The README's bash block containing `marker` (`what` names it in the failure) is an excerpt of
/// the walkthrough script: each of its lines is a line of the script, in the script's order.
fn assert_excerpt_of_walkthrough(marker: &str, what: &str) {
    let text = readme();
    let block = bash_blocks(&text)
        .into_iter()
        .find(|(_, lines)| lines.iter().any(|l| l.contains(marker)))
        .unwrap_or_else(|| panic!("the {what}"));
    let script = std::fs::read_to_string(Path::new(ROOT).join("scripts/api_walkthrough.sh")).unwrap();
    let script: Vec<&str> = script.lines().map(str::trim_start).collect();
    let mut at = 0;
    for (i, line) in block.1.iter().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        match script[at..].iter().position(|s| s == line) {
            Some(k) => at += k + 1,
            None => {
                panic!("README.md line {}: not a line of scripts/api_walkthrough.sh (in order): {line}", block.0 + i)
            }
        }
    }
}

/// The service block of the README is an excerpt of the walkthrough script.
#[test]
fn the_readme_service_block_is_an_excerpt_of_the_walkthrough() {
    assert_excerpt_of_walkthrough("wait_job()", "service block");
}

/// The README's ISO 9283 service example is an excerpt of the walkthrough too (so it runs as
/// written when the walkthrough runs).
#[test]
fn the_readme_iso9283_block_is_an_excerpt_of_the_walkthrough() {
    assert_excerpt_of_walkthrough("/v1/robots/$ROBOT/iso9283", "ISO 9283 service block");
}

struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `scripts/api_walkthrough.sh` against a server: every resource, exit 0 (it runs with
/// `set -euo pipefail` and curl `--fail-with-body`, so any failed call fails it).
#[test]
fn the_api_walkthrough_runs_against_a_server() {
    for tool in ["curl", "jq"] {
        let found = Command::new(tool).arg("--version").output().is_ok_and(|o| o.status.success());
        assert!(found, "{tool} is needed (.ci/run installs it)");
    }
    let dir = scratch("api");
    let port = common::free_port();
    let bin = env!("CARGO_BIN_EXE_robocal");
    let _server = Server(
        Command::new(bin)
            .args(["serve", "--db", dir.join("api.db").to_str().unwrap(), "--bind", &format!("127.0.0.1:{port}")])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let api = format!("http://127.0.0.1:{port}");
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "the server did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = Command::new("bash")
        .arg(Path::new(ROOT).join("scripts/api_walkthrough.sh"))
        .env("API", &api)
        .env("ROBOCAL", bin)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "scripts/api_walkthrough.sh exited {:?}\nstdout: {}\nstderr: {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    for section in ["== identification", "== validation", "== diagnosis", "== compensated targets"] {
        assert!(stdout.contains(section), "{section}: {stdout}");
    }
}

/// The README's custom robot example (a UR5, standard DH) is a robot file as written: it parses,
/// carries β on the joints after its parallel axes and every link's mass, and its nominal flange
/// at zero joints lies where the standard table puts it: (a2 + a3, −(d4 + d6), d1 − d5) =
/// (−817.25, −191.45, −5.491) mm.
#[test]
fn the_readme_custom_robot_example_is_a_robot_file() {
    let text = readme();
    let start = text.find("{\"name\": \"ur5\"").expect("the UR5 example");
    let end = start + text[start..].find("\n```").expect("its block's end");
    let v: serde_json::Value = serde_json::from_str(&text[start..end]).unwrap();
    let model = robocal::domain::robot::RobotSpec::from_json_value(&v).unwrap().to_model().unwrap();
    let with_beta: Vec<usize> = (0..6).filter(|&j| model.links[j].beta.is_some()).collect();
    assert_eq!(with_beta, vec![2, 3]);
    assert!(model.links.iter().all(|l| l.mass > 0.0));
    let set = robocal::kinematics::ParameterSet::nominal(model, robocal::kinematics::Tool::flange(), [0.0; 6]);
    let f = set.nominal_chain().fk(&robocal::kinematics::JointState::new(&[0.0; 6]));
    let mm = f.t / robocal::units::MM;
    // Standard DH at q = 0: x = a2 + a3, y = −(d4 + d6), z = d1 − d5.
    let expected = [-425.0 - 392.25, -(109.15 + 82.3), 89.159 - 94.65];
    for k in 0..3 {
        assert!((mm[k] - expected[k]).abs() < 1e-9, "flange {mm:?}, expected {expected:?}");
    }
}
