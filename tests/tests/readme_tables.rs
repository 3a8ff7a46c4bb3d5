//! README's recipe table is generated from the committed reports: the block between the
//! `recipe-table` markers must equal what `scripts/recipe_table.py docs/results/recipe` prints, so
//! a hand-edited number or a report added without regenerating the table fails here.
use std::path::Path;
use std::process::Command;

#[test]
fn readme_recipe_table_matches_the_committed_reports() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let open = "<!-- recipe-table: python3 scripts/recipe_table.py docs/results/recipe -->\n";
    let start = readme
        .find(open)
        .expect("README has the recipe-table start marker")
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
        "README's recipe table differs from the reports; regenerate it"
    );
}
