//! Tests of [`crate::output`].

use std::io::Write as _;

use super::*;

/// Every entry under `dir`, recursively, with the contents of files: what a test compares
/// before and after.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Option<Vec<u8>>)> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p.clone());
                out.push((p, None));
            } else {
                out.push((p.clone(), Some(fs::read(&p).unwrap())));
            }
        }
    }
    out.sort();
    out
}

fn hidden(dir: &Path) -> Vec<PathBuf> {
    snapshot(dir)
        .into_iter()
        .map(|(p, _)| p)
        .filter(|p| p.to_string_lossy().contains(".lidarsim-staging"))
        .collect()
}

/// A target directory holding an earlier run's two outputs and a file of the user's.
fn earlier_run(root: &Path) -> PathBuf {
    earlier_run_in(&root.join("out"))
}

fn earlier_run_in(out: &Path) -> PathBuf {
    let out = out.to_path_buf();
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("a.csv"), "old a\n").unwrap();
    fs::write(out.join("b.csv"), "old b\n").unwrap();
    fs::write(out.join("notes.txt"), "mine\n").unwrap();
    out
}

/// Staged CSV files never hold a non-finite number: `csv_number` writes an empty field, and
/// a file with `NaN` or `inf` in an unquoted field is refused, naming line and column;
/// text that reads so is quoted by `csv_field`, and quoted fields are text.
#[test]
fn csv_files_with_non_finite_numbers_are_refused() {
    assert_eq!(format!("{}", csv_number(0.25)), "0.25");
    assert_eq!(format!("{:.3e}", csv_number(1234.5)), "1.234e3");
    assert_eq!(format!("{:.2}", csv_number(-1.0 / 3.0)), "-0.33");
    for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(
            format!(
                "{}|{:.9e}|{:.4}",
                csv_number(x),
                csv_number(x),
                csv_number(x)
            ),
            "||"
        );
    }
    for text in ["NaN", "nan", "-inf", "+Infinity", " inf"] {
        assert!(reads_non_finite(text), "{text}");
        assert_eq!(csv_field(text), format!("'{text}"));
    }
    for text in ["info", "nano", "in", "1e308", ""] {
        assert!(!reads_non_finite(text), "{text}");
    }
    let ok = "# a comment, with nan\nname,x\n\"NaN\",1\n\"two\nlines, inf\",2\ninfo,3\n\"say \"\"inf\"\",\",4\n";
    assert_eq!(non_finite_field(ok.as_bytes()), None);
    let bad = "name,x,y\r\n\"a\nb\",1,2\r\nc,-inf,3\r\n";
    assert_eq!(
        non_finite_field(bad.as_bytes()),
        Some((4, "`x`".into(), "-inf".into()))
    );
    // A row wider than the header: its column by number.
    assert_eq!(
        non_finite_field(b"a\n3,NaN"),
        Some((2, "2".into(), "NaN".into()))
    );
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let before = snapshot(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    let e = set.write(out.join("b.csv"), bad).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "cannot write {}: line 4, column `x` is `-inf`: a value that cannot be computed must be an empty field (a bug in lidarsim; please report it)",
            out.join("b.csv").display()
        )
    );
    // However the file is written.
    let e = set
        .write_via(out.join("c.csv"), |p| fs::write(p, "x\nNaN\n"))
        .unwrap_err();
    assert!(matches!(e, OutputError::NonFinite { line: 2, .. }), "{e}");
    drop(set);
    assert_eq!(snapshot(root.path()), before);
    // Other files are not CSV.
    let mut set = OutputSet::new();
    set.write(out.join("notes.json"), "{\"x\": NaN}").unwrap();
}

#[test]
fn csv_field_quotes_only_what_needs_it() {
    assert_eq!(csv_field("on-line 1"), "on-line 1");
    assert_eq!(csv_field(""), "");
    assert_eq!(csv_field("a,b"), "\"a,b\"");
    assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
    assert_eq!(csv_field("cr\r"), "\"cr\r\"");
}

/// The text rule: a name that a reader would load as a number, a boolean or a missing value
/// (pandas' defaults) gets one apostrophe in front, and so does one that starts with an
/// apostrophe; `csv_text_value` undoes it. Other text is as it was.
#[test]
fn csv_field_marks_text_that_reads_as_a_number() {
    for (text, written) in [
        ("1064", "'1064"),
        ("-2.5e3", "'-2.5e3"),
        (" 7 ", "' 7 "),
        ("+1", "'+1"),
        (".5", "'.5"),
        ("NA", "'NA"),
        ("null", "'null"),
        ("None", "'None"),
        ("n/a", "'n/a"),
        ("True", "'True"),
        ("false", "'false"),
        ("'x", "''x"),
        ("'a,b", "\"''a,b\""),
    ] {
        assert_eq!(csv_field(text), written, "{text}");
        let unquoted = written
            .strip_prefix('"')
            .and_then(|w| w.strip_suffix('"'))
            .unwrap_or(written);
        assert_eq!(csv_text_value(unquoted), text);
    }
    for text in [
        "on", "off", "on-1", "1064nm", "R16e", "1/2", "high", "x'", "0x10", "1_000",
    ] {
        assert_eq!(csv_field(text), text);
        assert_eq!(csv_text_value(text), text);
    }
}

#[test]
fn a_new_directory_appears_with_all_its_files() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("deep/new/out");
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "a\n").unwrap();
    set.write_via(out.join("b.png"), |p| fs::write(p, "png"))
        .unwrap();
    assert!(
        !root.path().join("deep").exists(),
        "nothing before the commit"
    );
    let paths = set.commit().unwrap();
    assert_eq!(paths, [out.join("a.csv"), out.join("b.png")]);
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "a\n");
    assert_eq!(fs::read_to_string(out.join("b.png")).unwrap(), "png");
    assert_eq!(fs::read_dir(&out).unwrap().count(), 2);
    assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
}

#[test]
fn a_commit_replaces_an_earlier_runs_files_and_keeps_the_others() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(out.join("c.csv"), "new c\n").unwrap();
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "old a\n");
    set.commit().unwrap();
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
    assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
    assert_eq!(fs::read_to_string(out.join("c.csv")).unwrap(), "new c\n");
    assert_eq!(fs::read_to_string(out.join("notes.txt")).unwrap(), "mine\n");
    assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
}

#[test]
fn a_failed_file_leaves_everything_as_it_was() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let before = snapshot(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    // A plotting backend that fails after writing part of its file.
    let e = set
        .write_via(out.join("b.png"), |p| {
            fs::write(p, "half").unwrap();
            Err("out of fonts")
        })
        .unwrap_err();
    assert!(matches!(e, OutputError::Produce { .. }), "{e}");
    assert!(e.to_string().contains("b.png") && e.to_string().contains("out of fonts"));
    drop(set);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_full_disk_leaves_everything_as_it_was() {
    for fresh in [false, true] {
        let root = tempfile::tempdir().unwrap();
        let out = if fresh {
            root.path().join("new")
        } else {
            earlier_run(root.path())
        };
        let before = snapshot(root.path());
        let mut set = OutputSet::new();
        set.write(out.join("a.csv"), "new a\n").unwrap();
        // What a full disk does to a writer: part of the bytes, then ENOSPC.
        let e = set
            .write_with(out.join("b.csv"), |f| {
                f.write_all(b"new b, first half")?;
                Err(io::Error::from(io::ErrorKind::StorageFull))
            })
            .unwrap_err();
        match &e {
            OutputError::Io { path, error } => {
                assert_eq!(path, &out.join("b.csv"));
                assert_eq!(error.kind(), io::ErrorKind::StorageFull);
            }
            other => panic!("{other}"),
        }
        drop(set);
        assert_eq!(snapshot(root.path()), before);
    }
}

#[test]
fn a_failed_file_is_not_committed() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("out");
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "a").unwrap();
    assert!(set.write_via(out.join("b.png"), |_| Err("no")).is_err());
    set.commit().unwrap();
    assert_eq!(fs::read_dir(&out).unwrap().count(), 1);
    assert!(out.join("a.csv").is_file());
}

#[test]
fn a_directory_named_like_an_output_is_refused_before_writing() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    fs::create_dir(out.join("d.csv")).unwrap();
    let before = snapshot(root.path());
    let e = check_paths(&[out.join("a.csv"), out.join("d.csv")]).unwrap_err();
    assert!(matches!(&e, OutputError::DirectoryInTheWay(p) if p == &out.join("d.csv")));
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    let mut called = false;
    let e = set
        .write_with(out.join("d.csv"), |_| {
            called = true;
            Ok(())
        })
        .unwrap_err();
    assert!(!called, "nothing is written for a blocked name");
    assert_eq!(
        e.to_string(),
        format!(
            "cannot write {}: a directory of that name is in the way",
            out.join("d.csv").display()
        )
    );
    drop(set);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_directory_that_appears_before_the_commit_is_refused_by_it() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(out.join("c.csv"), "new c\n").unwrap();
    fs::create_dir(out.join("c.csv")).unwrap();
    let before: Vec<_> = snapshot(root.path())
        .into_iter()
        .filter(|(p, _)| !p.to_string_lossy().contains(".lidarsim-staging"))
        .collect();
    let e = set.commit().unwrap_err();
    assert!(matches!(&e, OutputError::DirectoryInTheWay(p) if p == &out.join("c.csv")));
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn paths_that_cannot_be_files_are_refused() {
    let root = tempfile::tempdir().unwrap();
    let file = root.path().join("file");
    fs::write(&file, "x").unwrap();
    let e = check_paths(&[file.join("sub/a.csv")]).unwrap_err();
    assert!(
        matches!(&e, OutputError::NotADirectory { dir, .. } if dir == &file),
        "{e}"
    );
    let mut set = OutputSet::new();
    assert!(matches!(
        set.write(file.join("a.csv"), "a"),
        Err(OutputError::NotADirectory { .. })
    ));
    assert!(matches!(
        check_paths(&[Path::new("..")]),
        Err(OutputError::NotAFileName(_))
    ));
    let a = root.path().join("out/a.csv");
    let again = root.path().join("out/./a.csv");
    assert!(matches!(
        check_paths(&[&a, &again]),
        Err(OutputError::Twice(_))
    ));
    set.write(&a, "a").unwrap();
    assert!(matches!(set.write(&again, "b"), Err(OutputError::Twice(_))));
    drop(set);
    assert_eq!(fs::read_dir(root.path()).unwrap().count(), 1);
}

/// A named pipe where an output goes is refused before writing and at the commit, and is
/// left as it was: a whole-or-nothing write would replace it by a regular file (fuzz
/// finding F12: `--out /dev/null` replaced the machine's /dev/null).
#[cfg(unix)]
#[test]
fn a_pipe_or_device_is_never_replaced() {
    use std::os::unix::fs::FileTypeExt;
    let root = tempfile::tempdir().unwrap();
    let fifo = root.path().join("a.csv");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        println!("skipped: mkfifo is not available");
        return;
    }
    assert!(matches!(
        check_paths(&[&fifo]),
        Err(OutputError::NotARegularFile(_))
    ));
    let mut set = OutputSet::new();
    assert!(matches!(
        set.write(&fifo, "a\n"),
        Err(OutputError::NotARegularFile(_))
    ));
    // A pipe that appears between staging and the commit.
    let late = root.path().join("c.csv");
    set.write(&late, "c\n").unwrap();
    std::process::Command::new("mkfifo")
        .arg(&late)
        .status()
        .unwrap();
    assert!(matches!(set.commit(), Err(OutputError::NotARegularFile(_))));
    for p in [&fifo, &late] {
        assert!(fs::symlink_metadata(p).unwrap().file_type().is_fifo());
    }
    fs::remove_file(&late).unwrap();
    // And an earlier run's name held by a pipe is not removed as stale.
    let mut set = OutputSet::new();
    set.replaces(root.path(), &["a.csv"]).unwrap();
    set.write(root.path().join("b.csv"), "b\n").unwrap();
    set.commit().unwrap();
    assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
    // /dev/null itself, where it exists, is refused before any work.
    if Path::new("/dev/null").exists() {
        assert!(matches!(
            check_paths(&[Path::new("/dev/null")]),
            Err(OutputError::NotARegularFile(_))
        ));
    }
}

#[test]
fn a_rename_that_fails_midway_is_undone() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let before = snapshot(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("c.csv"), "new c\n").unwrap();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(out.join("b.csv"), "new b\n").unwrap();
    let mut n = 0;
    let e = set
        .commit_with(&mut |from, to| {
            n += 1;
            if n == 3 {
                return Err(io::ErrorKind::StorageFull.into());
            }
            fs::rename(from, to)
        })
        .unwrap_err();
    assert!(matches!(&e, OutputError::Commit { path, .. } if path == &out.join("b.csv")));
    assert!(e.to_string().ends_with("no output was changed"), "{e}");
    drop(set);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_new_directory_is_taken_back_when_a_later_one_fails() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run_in(&root.path().join("runs/2026/out"));
    // Shallower, so committed first; its parent `new` is made for it.
    let fresh = root.path().join("new/figures");
    let before = snapshot(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(fresh.join("f.png"), "png").unwrap();
    let mut moved_fresh = false;
    let e = set
        .commit_with(&mut |from, to| {
            if to.starts_with(&out) {
                return Err(io::ErrorKind::PermissionDenied.into());
            }
            moved_fresh |= to == fresh;
            fs::rename(from, to)
        })
        .unwrap_err();
    assert!(
        moved_fresh,
        "the new directory was moved before the failure"
    );
    assert!(matches!(e, OutputError::Commit { .. }), "{e}");
    drop(set);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn an_undo_that_fails_names_the_new_files_and_keeps_the_old_ones() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    let mut set = OutputSet::new();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(out.join("b.csv"), "new b\n").unwrap();
    let mut n = 0;
    // The second move fails, and so does putting the old a.csv back.
    let e = set
        .commit_with(&mut |from, to| {
            n += 1;
            if n >= 2 {
                return Err(io::ErrorKind::StorageFull.into());
            }
            fs::rename(from, to)
        })
        .unwrap_err();
    let OutputError::PartlyCommitted {
        path, new, kept, ..
    } = &e
    else {
        panic!("{e}");
    };
    assert_eq!(path, &out.join("b.csv"));
    assert_eq!(&**new, &[out.join("a.csv")]);
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
    assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
    let msg = e.to_string();
    assert!(msg.contains(&format!("{} is from this run", out.join("a.csv").display())));
    drop(set);
    // The only copy of the old a.csv is not deleted.
    assert_eq!(fs::read_to_string(&kept[0]).unwrap(), "old a\n");
}

/// An earlier run's outputs that this set does not rewrite are removed by the commit; files
/// of other names (the user's), and a directory of an output's name, are left alone.
#[test]
fn a_commit_removes_the_earlier_outputs_it_does_not_rewrite() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    fs::create_dir(out.join("d.png")).unwrap();
    let mut set = OutputSet::new();
    set.replaces(&out, &["a.csv", "b.csv", "c.csv", "d.png"])
        .unwrap();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    assert_eq!(fs::read_to_string(out.join("b.csv")).unwrap(), "old b\n");
    set.commit().unwrap();
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
    assert!(!out.join("b.csv").exists(), "the stale b.csv is gone");
    assert_eq!(fs::read_to_string(out.join("notes.txt")).unwrap(), "mine\n");
    assert!(out.join("d.png").is_dir());
    assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
    // Into a new directory there is nothing to remove.
    let fresh = root.path().join("fresh");
    let mut set = OutputSet::new();
    set.replaces(&fresh, &["a.csv", "b.csv"]).unwrap();
    set.write(fresh.join("a.csv"), "a").unwrap();
    set.commit().unwrap();
    assert_eq!(fs::read_dir(&fresh).unwrap().count(), 1);
}

/// A commit that fails after a stale file went (the removal of the next fails) puts it
/// back, and the new files go: nothing changed.
#[test]
fn a_failed_commit_puts_the_stale_outputs_back() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    fs::write(out.join("c.csv"), "old c\n").unwrap();
    let fresh = root.path().join("fresh");
    let before = snapshot(root.path());
    let mut set = OutputSet::new();
    set.replaces(&out, &["a.csv", "b.csv", "c.csv"]).unwrap();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    set.write(fresh.join("f.csv"), "f\n").unwrap();
    let mut removed_b = false;
    let e = set
        .commit_with(&mut |from, to| {
            if from == out.join("c.csv") {
                assert!(removed_b, "b.csv went first");
                return Err(io::ErrorKind::StorageFull.into());
            }
            removed_b |= from == out.join("b.csv");
            fs::rename(from, to)
        })
        .unwrap_err();
    assert!(
        matches!(&e, OutputError::Commit { path, .. } if path == &out.join("c.csv")),
        "{e}"
    );
    drop(set);
    assert_eq!(snapshot(root.path()), before);
}

/// If a stale file cannot be put back, the error says it was removed and where it is kept.
#[test]
fn a_stale_output_that_cannot_be_put_back_is_named() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    fs::write(out.join("c.csv"), "old c\n").unwrap();
    let mut set = OutputSet::new();
    set.replaces(&out, &["a.csv", "b.csv", "c.csv"]).unwrap();
    set.write(out.join("a.csv"), "new a\n").unwrap();
    let e = set
        .commit_with(&mut |from, to| {
            if from == out.join("c.csv") || to == out.join("b.csv") {
                return Err(io::ErrorKind::StorageFull.into());
            }
            fs::rename(from, to)
        })
        .unwrap_err();
    let OutputError::PartlyCommitted {
        new, removed, kept, ..
    } = &e
    else {
        panic!("{e}");
    };
    assert!(new.is_empty(), "a.csv was put back: {new:?}");
    assert_eq!(&**removed, &[out.join("b.csv")]);
    assert!(
        e.to_string().contains(&format!(
            "{} was removed (the previous versions are kept as {})",
            out.join("b.csv").display(),
            kept[0].display()
        )),
        "{e}"
    );
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "old a\n");
    assert_eq!(fs::read_to_string(out.join("c.csv")).unwrap(), "old c\n");
    drop(set);
    assert_eq!(fs::read_to_string(&kept[0]).unwrap(), "old b\n");
}

#[test]
fn write_file_replaces_one_file() {
    let root = tempfile::tempdir().unwrap();
    let out = earlier_run(root.path());
    write_file(out.join("a.csv"), b"new a\n").unwrap();
    assert_eq!(fs::read_to_string(out.join("a.csv")).unwrap(), "new a\n");
    assert_eq!(hidden(root.path()), Vec::<PathBuf>::new());
}
