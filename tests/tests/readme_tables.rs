//! The documents that claim to mirror something: the recipe table of `docs/status.md` is
//! generated from the committed reports (the block between the `recipe-table` markers must equal
//! what `scripts/recipe_table.py docs/results/recipe` prints, so a hand-edited number or a report
//! added without regenerating the table fails here), and README's layout tree is the tracked tree.
use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

#[test]
fn status_recipe_table_matches_the_committed_reports() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("docs/status.md")).expect("docs/status.md");
    let open = "<!-- recipe-table: python3 scripts/recipe_table.py docs/results/recipe -->\n";
    let start = readme
        .find(open)
        .expect("docs/status.md has the recipe-table start marker")
        + open.len();
    let end = readme[start..]
        .find("<!-- /recipe-table -->")
        .expect("README has the end marker")
        + start;
    let in_readme = readme[start..end].trim();

    let output = Command::new("python3")
        .arg("scripts/recipe_table.py")
        .arg("docs/results/recipe")
        .current_dir(&root)
        .output()
        .expect("python3 runs (CI installs it)");
    assert!(
        output.status.success(),
        "recipe_table.py failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let generated = String::from_utf8(output.stdout).expect("UTF-8 table");
    assert_eq!(
        in_readme,
        generated.trim(),
        "the recipe table of docs/status.md differs from the reports; regenerate it"
    );
}

/// README's layout tree (the `text` block under `## Layout`): a line names files and directories
/// (ending in `/`, possibly several path segments) before its description (two or more spaces
/// on); deeper lines sit in the line's last directory.
fn layout_tree(readme: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let section = &readme[readme
        .find("## Layout")
        .expect("README has a Layout section")..];
    let start = section
        .find("```text\n")
        .expect("the layout is a text block")
        + 8;
    let block = &section[start..start + section[start..].find("```").expect("block end")];
    let (mut dirs, mut files) = (BTreeSet::new(), BTreeSet::new());
    let mut parents: Vec<(usize, String)> = Vec::new();
    for line in block.lines().filter(|l| !l.trim().is_empty()) {
        let indent = line.len() - line.trim_start().len();
        let entry = line.trim_start().split("  ").next().unwrap_or_default();
        while parents.last().is_some_and(|(depth, _)| *depth >= indent) {
            parents.pop();
        }
        let parent = parents.last().map(|(_, p)| p.clone()).unwrap_or_default();
        let mut last_dir = None;
        for name in entry.split(' ').filter(|n| !n.is_empty()) {
            let path = format!("{parent}{name}");
            if name.ends_with('/') {
                let mut prefix = String::new();
                for part in path.trim_end_matches('/').split('/') {
                    prefix.push_str(part);
                    dirs.insert(prefix.clone());
                    prefix.push('/');
                }
                last_dir = Some(path);
            } else {
                files.insert(path);
            }
        }
        if let Some(dir) = last_dir {
            parents.push((indent, dir));
        }
    }
    (dirs, files)
}

#[test]
fn readme_layout_names_every_directory_and_only_real_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let (dirs, files) = layout_tree(&readme);
    let output = Command::new("git")
        .args(["ls-files"])
        .current_dir(&root)
        .output()
        .expect("git runs");
    assert!(output.status.success(), "git ls-files failed");
    let tracked: BTreeSet<String> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .flat_map(|file| {
            let parts: Vec<&str> = file.split('/').collect();
            (1..parts.len()).map(move |n| parts[..n].join("/"))
        })
        // The reports under docs/results/ and the LeRobot datasets (their own chunk-*/ layout)
        // are data: the tree names the folder only.
        .filter(|dir| {
            !dir.starts_with("docs/results/") && !dir.starts_with("frmd-host/tests/data/lerobot/")
        })
        .collect();
    let missing: Vec<&String> = tracked.difference(&dirs).collect();
    let extra: Vec<&String> = dirs.difference(&tracked).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "README's layout misses directories {missing:?} and names ones that are not tracked {extra:?}"
    );
    let absent: Vec<&String> = files.iter().filter(|f| !root.join(f).is_file()).collect();
    assert!(
        absent.is_empty(),
        "README's layout names missing files {absent:?}"
    );
    assert!(
        files.len() > 20,
        "the layout names files too ({} found)",
        files.len()
    );
}
