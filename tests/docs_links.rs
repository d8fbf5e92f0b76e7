//! The documentation stays true: every relative link in `README.md` and `docs/**/*.md` points
//! at a file or folder of the repository, and every `#anchor` at a heading of the target page
//! (GitHub's heading ids); every code fence names its language; every page with Rust code is
//! compiled as a doc test (`src/lib.rs` includes it); the README keeps its quick-start commands
//! and stays a front page.
use std::collections::{BTreeSet, HashMap};
use std::fs;
use std::path::{Component, Path, PathBuf};

/// The repository root.
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `README.md` and every `.md` file under `docs/`, relative to the root, sorted.
fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, root: &Path, out: &mut Vec<PathBuf>) {
        let mut entries: Vec<PathBuf> = fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.expect("directory entry").path())
            .collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, root, out);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p.strip_prefix(root).expect("under the root").to_path_buf());
            }
        }
    }
    let root = root();
    let mut out = vec![PathBuf::from("README.md")];
    walk(&root.join("docs"), &root, &mut out);
    out
}

/// A line of a page with its number (1-based), outside or inside a code fence.
struct Line<'a> {
    number: usize,
    text: &'a str,
    in_fence: bool,
}

/// Splits a page into lines, marking those inside fenced code blocks (the fence lines
/// themselves count as inside). Returns the lines and each opening fence's info string.
fn lines(text: &str) -> (Vec<Line<'_>>, Vec<(usize, String)>) {
    let mut out = Vec::new();
    let mut fences = Vec::new();
    let mut open: Option<(char, usize)> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let fence = ['`', '~'].into_iter().find_map(|c| {
            let n = trimmed.chars().take_while(|&x| x == c).count();
            (n >= 3 && indent < 4).then_some((c, n))
        });
        match (open, fence) {
            (None, Some((c, n))) => {
                open = Some((c, n));
                fences.push((i + 1, trimmed[n..].trim().to_string()));
                out.push(Line {
                    number: i + 1,
                    text: line,
                    in_fence: true,
                });
            }
            (Some((c, n)), Some((c2, n2)))
                if c == c2 && n2 >= n && trimmed[n2..].trim().is_empty() =>
            {
                open = None;
                out.push(Line {
                    number: i + 1,
                    text: line,
                    in_fence: true,
                });
            }
            (o, _) => out.push(Line {
                number: i + 1,
                text: line,
                in_fence: o.is_some(),
            }),
        }
    }
    (out, fences)
}

/// Removes inline code spans (`` `...` ``, any number of backticks) from a line.
fn strip_code_spans(line: &str) -> String {
    let b = line.as_bytes();
    let mut out = String::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'`' {
            let n = b[i..].iter().take_while(|&&c| c == b'`').count();
            let tick = "`".repeat(n);
            if let Some(end) = line[i + n..].find(&tick) {
                i += n + end + n;
                continue;
            }
            out.push_str(&line[i..i + n]);
            i += n;
            continue;
        }
        let ch = line[i..].chars().next().expect("in bounds");
        out.push(ch);
        i += ch.len_utf8();
    }
    out
}

/// The link destinations of one line (code spans removed): inline links and images
/// `[text](dest "title")`, reference definitions `[label]: dest`, and HTML `href`/`src`.
fn link_targets(line: &str) -> Vec<String> {
    let line = strip_code_spans(line);
    let mut out = Vec::new();
    // Reference definition.
    let t = line.trim_start();
    if t.starts_with('[') {
        if let Some(close) = t.find("]:") {
            if !t[1..close].contains(']') {
                if let Some(dest) = t[close + 2..].split_whitespace().next() {
                    out.push(dest.trim_matches(|c| c == '<' || c == '>').to_string());
                }
                return out;
            }
        }
    }
    // Inline links: "](" followed by a destination up to the matching ")".
    let mut rest = line.as_str();
    while let Some(pos) = rest.find("](") {
        let after = &rest[pos + 2..];
        let mut depth = 0usize;
        let mut end = after.len();
        for (i, c) in after.char_indices() {
            match c {
                '(' => depth += 1,
                ')' if depth == 0 => {
                    end = i;
                    break;
                }
                ')' => depth -= 1,
                _ => {}
            }
        }
        let inner = after[..end].trim();
        let dest = if let Some(stripped) = inner.strip_prefix('<') {
            stripped.split('>').next().unwrap_or("").to_string()
        } else {
            inner.split_whitespace().next().unwrap_or("").to_string()
        };
        out.push(dest);
        rest = &after[end.min(after.len())..];
    }
    // HTML attributes.
    for attr in ["href=\"", "src=\""] {
        let mut rest = line.as_str();
        while let Some(pos) = rest.find(attr) {
            let after = &rest[pos + attr.len()..];
            let end = after.find('"').unwrap_or(after.len());
            out.push(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

/// GitHub's id for a heading's text (github-slugger): the rendered text lowercased, every
/// character other than a letter, digit, `-`, `_` or space dropped, spaces turned into `-`.
fn slug(heading: &str) -> String {
    // Rendered text: code spans keep their content, links their text, emphasis disappears.
    let mut text = String::new();
    let mut rest = heading;
    while let Some(pos) = rest.find("](") {
        let (before, after) = rest.split_at(pos);
        text.push_str(before);
        let end = after.find(')').map_or(after.len(), |e| e + 1);
        rest = &after[end..];
    }
    text.push_str(rest);
    let text = text.replace(['`', '*', '[', ']'], "");
    text.trim()
        .chars()
        .flat_map(char::to_lowercase)
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The anchors a page defines: its headings' GitHub ids (repeats get `-1`, `-2`, ...) and
/// HTML `id`/`name` attributes.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut out = BTreeSet::new();
    for line in lines(text).0.iter().filter(|l| !l.in_fence) {
        let t = line.text.trim_start();
        let hashes = t.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && t[hashes..].starts_with([' ', '\t']) {
            let title = t[hashes..].trim().trim_end_matches('#').trim_end();
            let base = slug(title);
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 {
                base.clone()
            } else {
                format!("{base}-{n}")
            });
            *n += 1;
        }
        for attr in ["id=\"", "name=\""] {
            let mut rest = line.text;
            while let Some(pos) = rest.find(attr) {
                let after = &rest[pos + attr.len()..];
                let end = after.find('"').unwrap_or(after.len());
                out.insert(after[..end].to_string());
                rest = &after[end..];
            }
        }
    }
    out
}

/// Decodes `%XX` escapes of a link path.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && b[i + 1].is_ascii_hexdigit()
            && b[i + 2].is_ascii_hexdigit()
        {
            let hex = std::str::from_utf8(&b[i + 1..i + 3]).expect("ASCII hex digits");
            out.push(u8::from_str_radix(hex, 16).expect("two hex digits"));
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Joins `rel` onto the folder `dir` (both relative to the root), resolving `.` and `..`;
/// `None` if it leaves the repository.
fn resolve(dir: &Path, rel: &str) -> Option<PathBuf> {
    let mut parts: Vec<String> = dir
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    for c in Path::new(rel).components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::Normal(p) => parts.push(p.to_string_lossy().into_owned()),
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(parts.iter().collect())
}

/// Every broken link of the pages in `files` (path relative to `root` → text), as
/// `page:line: message`. Targets are looked up in `files` first, then on disk under `root`.
fn broken_links(root: &Path, files: &[(PathBuf, String)]) -> Vec<String> {
    let texts: HashMap<&Path, &str> = files
        .iter()
        .map(|(p, t)| (p.as_path(), t.as_str()))
        .collect();
    let mut anchor_cache: HashMap<PathBuf, BTreeSet<String>> = HashMap::new();
    let mut errors = Vec::new();
    for (page, text) in files {
        let dir = page.parent().unwrap_or(Path::new(""));
        for line in lines(text).0.iter().filter(|l| !l.in_fence) {
            for dest in link_targets(line.text) {
                let at = format!("{}:{}", page.display(), line.number);
                if dest.is_empty() {
                    errors.push(format!("{at}: empty link"));
                    continue;
                }
                if dest.contains("://") || dest.starts_with("mailto:") {
                    continue;
                }
                if dest.starts_with('/') {
                    errors.push(format!("{at}: {dest}: absolute path; use a relative link"));
                    continue;
                }
                let (path, anchor) = match dest.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (dest.as_str(), None),
                };
                let target = if path.is_empty() {
                    page.clone()
                } else {
                    match resolve(dir, &percent_decode(path)) {
                        Some(t) => t,
                        None => {
                            errors.push(format!("{at}: {dest}: leaves the repository"));
                            continue;
                        }
                    }
                };
                let known = texts.contains_key(target.as_path());
                if !known && !root.join(&target).exists() {
                    errors.push(format!("{at}: {dest}: {} does not exist", target.display()));
                    continue;
                }
                let Some(anchor) = anchor else { continue };
                if target.extension().is_none_or(|x| x != "md") {
                    errors.push(format!(
                        "{at}: {dest}: an anchor into a file that is not Markdown"
                    ));
                    continue;
                }
                let set = anchor_cache.entry(target.clone()).or_insert_with(|| {
                    let text = match texts.get(target.as_path()) {
                        Some(t) => t.to_string(),
                        None => fs::read_to_string(root.join(&target)).unwrap_or_default(),
                    };
                    anchors(&text)
                });
                if !set.contains(&percent_decode(anchor)) {
                    errors.push(format!(
                        "{at}: {dest}: no heading with id #{anchor} in {} (ids: {})",
                        target.display(),
                        set.iter().cloned().collect::<Vec<_>>().join(", ")
                    ));
                }
            }
        }
    }
    errors
}

fn read_pages() -> Vec<(PathBuf, String)> {
    let root = root();
    pages()
        .into_iter()
        .map(|p| {
            let text = fs::read_to_string(root.join(&p))
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, text)
        })
        .collect()
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let files = read_pages();
    assert!(
        files.len() > 5,
        "README.md and docs/ pages found: {}",
        files.len()
    );
    let errors = broken_links(&root(), &files);
    assert!(errors.is_empty(), "broken links:\n{}", errors.join("\n"));
}

#[test]
fn every_code_fence_names_its_language() {
    // rustdoc compiles a fence without a language as Rust; GitHub shows it unhighlighted.
    let mut bare = Vec::new();
    for (page, text) in read_pages() {
        for (line, info) in lines(&text).1 {
            if info.is_empty() {
                bare.push(format!("{}:{line}", page.display()));
            }
        }
    }
    assert!(
        bare.is_empty(),
        "code fences without a language (use rust, sh, python, text, ...): {}",
        bare.join(", ")
    );
}

#[test]
fn every_page_with_rust_code_is_a_doc_test() {
    let lib = fs::read_to_string(root().join("src/lib.rs")).expect("src/lib.rs");
    let mut missing = Vec::new();
    for (page, text) in read_pages() {
        let rust = lines(&text).1.iter().any(|(_, info)| {
            let lang = info.split([',', ' ']).next().unwrap_or("");
            lang == "rust"
        });
        let include = format!("include_str!(\"../{}\")", page.display());
        if rust && !lib.contains(&include) {
            missing.push(page.display().to_string());
        }
    }
    assert!(
        missing.is_empty(),
        "pages with Rust code that src/lib.rs does not compile as doc tests \
         (add `#[doc = include_str!(\"../PAGE\")]` there): {}",
        missing.join(", ")
    );
}

#[test]
fn readme_keeps_the_quick_start_and_stays_short() {
    let readme = fs::read_to_string(root().join("README.md")).expect("README.md");
    // Users run these two lines as they are, and .ci/run runs them first, read out of the
    // first ```sh block under "## Quick start" (what `quick_start_block` reads here).
    let expected = [
        "bash .ci/setup && cargo run --release --no-default-features --features cli -- rollout",
        "bash .ci/setup && cargo test --release --no-default-features --features cli && bash .ci/python-tests",
    ];
    assert_eq!(
        quick_start_block(&readme),
        expected,
        "README.md's quick-start block changed"
    );
    let ci = fs::read_to_string(root().join(".ci/run")).expect(".ci/run");
    for part in [
        "/^## Quick start/",
        r#"bash -c "${quick_start[$i]}""#,
        "cargo test --release --workspace",
        "bash .ci/python-tests",
        "MJSKILL_REQUIRE_FEATURES=1",
        "cargo tree -p mjskill --no-default-features",
    ] {
        assert!(ci.contains(part), ".ci/run no longer runs `{part}`");
    }
    let n = readme.lines().count();
    assert!(
        n <= 220,
        "README.md has {n} lines; it is the front page (at most about 200): move reference \
         material to docs/ and link it"
    );
}

/// The non-empty lines of the first ```sh block in the README's "## Quick start" section, as
/// .ci/run's awk reads them.
fn quick_start_block(readme: &str) -> Vec<&str> {
    let section = readme
        .split("\n## ")
        .find(|s| s.starts_with("Quick start"))
        .unwrap_or("");
    let Some(start) = section.find("```sh\n") else {
        return Vec::new();
    };
    let block = &section[start + 6..];
    block
        .lines()
        .take_while(|l| !l.starts_with("```"))
        .filter(|l| !l.trim().is_empty())
        .collect()
}

#[test]
fn github_heading_ids() {
    assert_eq!(slug("3. fetch"), "3-fetch");
    assert_eq!(slug("Many envs: `VecEnv`"), "many-envs-vecenv");
    assert_eq!(
        slug("Ray: sharded recorded rollouts (`pip install 'mjskill[ray]'`)"),
        "ray-sharded-recorded-rollouts-pip-install-mjskillray"
    );
    assert_eq!(slug("Speed — from Python"), "speed--from-python");
    assert_eq!(slug("The [README](../README.md) page"), "the-readme-page");
    assert_eq!(
        slug("4. Flat `state` dimensions"),
        "4-flat-state-dimensions"
    );
    let ids =
        anchors("# A\n\n## Notes\n\n```sh\n# not a heading\n```\n\n## Notes\n<a id=\"x\"></a>\n");
    let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
    assert_eq!(ids, ["a", "notes", "notes-1", "x"]);
}

#[test]
fn the_checker_finds_broken_links() {
    let files = vec![
        (
            PathBuf::from("docs/a.md"),
            "# A\n\n## Part one\n\n[ok](b.md#b) [ok too](#part-one) [code](../Cargo.toml) \
             `[not a link](nowhere.md)`\n\n```text\n[in a fence](nowhere.md)\n```\n\
             [gone](missing.md) [bad anchor](b.md#nope) [out](../../x.md) [web](https://example.com/x)\n"
                .to_string(),
        ),
        (PathBuf::from("docs/b.md"), "# B\n\n[up](../README.md) [self](a.md#part-one)\n".to_string()),
    ];
    let errors = broken_links(&root(), &files);
    assert_eq!(errors.len(), 3, "{errors:#?}");
    assert!(
        errors[0].contains("docs/a.md:10: missing.md"),
        "{errors:#?}"
    );
    assert!(
        errors[1].contains("b.md#nope") && errors[1].contains("no heading"),
        "{errors:#?}"
    );
    assert!(errors[2].contains("leaves the repository"), "{errors:#?}");
}
