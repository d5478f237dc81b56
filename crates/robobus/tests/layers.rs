//! The library's layers run one way: no import circle inside `crates/robobus/src`.
//!
//! The test reads every file of the library (from `lib.rs`, following its `mod`
//! declarations), builds the graph of which file uses which, and fails naming every
//! circle: each strongly connected set of more than one node, with the lines that make
//! its edges.
//!
//! # What an edge is
//!
//! A file uses another when its code names something that lives there: a `use` of it
//! (`use crate::ops::OpError;`, `use super::Report;`, a group `use super::{a, b::C};`),
//! or a path in code (`crate::ops::read_bounded(...)`, `super::Family::Wck`, a child
//! module's `dispatch::run(...)`). Each path is resolved to the file of the module that
//! holds the named item, following re-exports (`crate::ErrorKind` is `error.rs`, which
//! `lib.rs` re-exports; `catalogue::Station` would be `station/mod.rs`) and glob
//! re-exports (`pub use checks::*`).
//!
//! Not an edge:
//! - a module's `pub use` (any `pub(..)` too) of something in its own descendants: a
//!   parent naming its children's items (`pub use dispatch::run;`) only gives them a
//!   shorter path, and whoever uses that path gets the edge to the child itself;
//! - test code (`#[cfg(test)]` items, test modules) and documentation (comments, doc
//!   comments and their links, string literals): a test or a doc link may reach anywhere;
//! - paths outside the crate (`std::`, `robobus_link::`, ...).
//!
//! # What is checked
//!
//! - **Between top-level modules, strictly**: every edge from a file of one top-level
//!   module (`error`, `wck`, `whj`, `actuator`, `ops`, `robot`, `station`, `catalogue`,
//!   `record`, `frontend`, ...) to a file of another counts, re-exports included, and the
//!   graph of top-level modules has no circle.
//! - **Between the files of one top-level module**: the same edges among its files have
//!   no circle either, less a file's use of what one of its ancestors defines (`use
//!   super::Request;` where `mod.rs` defines `Request`): a child module is a part of its
//!   parent split out, and the two may use each other. Between siblings and cousins every
//!   edge counts (`use super::plan::Plan;` is `dispatch.rs` using `plan.rs`, and so is
//!   `super::run` when the parent only re-exports `run` from `dispatch.rs`): a type two
//!   of them both need lives in the lower one.

#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

/// A module: its file and what it names.
#[derive(Debug, Default)]
struct Module {
    /// The file (relative to `src`) holding it; an inline module shares its parent's.
    file: String,
    /// Child modules (not test ones).
    children: BTreeSet<String>,
    /// `use` bindings: the name bound and what it names.
    imports: Vec<Import>,
    /// Names of items defined in it (functions, types, constants, macros).
    defined: BTreeSet<String>,
}

/// One binding of a `use` statement.
#[derive(Debug, Clone)]
struct Import {
    /// The path as written (`super`, `crate`, `self` or a name in scope first).
    path: Vec<String>,
    /// The bound name, `*` for a glob.
    name: String,
    /// `pub`, `pub(crate)`, `pub(super)`: a re-export.
    public: bool,
    /// Line of the statement.
    line: usize,
}

/// A path in code (outside `use`): where it appears and the module it appears in.
#[derive(Debug)]
struct Reference {
    module: Vec<String>,
    path: Vec<String>,
    line: usize,
}

/// An edge's evidence: `file:line path`.
type Evidence = BTreeMap<(String, String), Vec<String>>;

/// The whole crate as parsed.
#[derive(Debug, Default)]
struct Crate {
    modules: BTreeMap<Vec<String>, Module>,
    references: Vec<Reference>,
}

// ---------------------------------------------------------------------------------------
// Reading: comments, strings and test code blanked out, then tokens.

/// The text with comments and string / char literals replaced by spaces (newlines kept,
/// so offsets and line numbers stay).
fn blank_comments_and_literals(src: &str) -> String {
    let bytes = src.as_bytes();
    let mut out = bytes.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(bytes.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        if c == b'/' && bytes.get(i + 1) == Some(&b'/') {
            let end = src[i..].find('\n').map_or(bytes.len(), |n| i + n);
            blank(&mut out, i, end);
            i = end;
        } else if c == b'/' && bytes.get(i + 1) == Some(&b'*') {
            let (mut depth, mut j) = (1, i + 2);
            while j < bytes.len() && depth > 0 {
                if bytes[j] == b'/' && bytes.get(j + 1) == Some(&b'*') {
                    depth += 1;
                    j += 2;
                } else if bytes[j] == b'*' && bytes.get(j + 1) == Some(&b'/') {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if c == b'r'
            && (i == 0
                || !ident(bytes[i - 1])
                || (i >= 1
                    && matches!(bytes[i - 1], b'b' | b'c')
                    && (i < 2 || !ident(bytes[i - 2]))))
            && matches!(bytes.get(i + 1), Some(b'"' | b'#'))
        {
            // A raw string r"..", r#".."#, or an identifier starting with r#.
            let mut j = i + 1;
            while bytes.get(j) == Some(&b'#') {
                j += 1;
            }
            if bytes.get(j) != Some(&b'"') {
                i = j; // r#ident
                continue;
            }
            let hashes = j - i - 1;
            let mut k = j + 1;
            loop {
                if k >= bytes.len() {
                    break;
                }
                if bytes[k] == b'"'
                    && bytes[k + 1..]
                        .iter()
                        .take(hashes)
                        .filter(|&&h| h == b'#')
                        .count()
                        == hashes
                {
                    k += 1 + hashes;
                    break;
                }
                k += 1;
            }
            blank(&mut out, i, k);
            i = k;
        } else if c == b'"' {
            let mut j = i + 1;
            while j < bytes.len() && bytes[j] != b'"' {
                j += if bytes[j] == b'\\' { 2 } else { 1 };
            }
            blank(&mut out, i, j + 1);
            i = j + 1;
        } else if c == b'\'' {
            // A char literal ('x', '\n', '\u{..}', 'é') or a lifetime / label ('a).
            if bytes.get(i + 1) == Some(&b'\\') {
                let mut j = i + 3;
                while j < bytes.len() && bytes[j] != b'\'' {
                    j += 1;
                }
                blank(&mut out, i, j + 1);
                i = j + 1;
            } else if let Some(ch) = src[i + 1..].chars().next() {
                let after = i + 1 + ch.len_utf8();
                if bytes.get(after) == Some(&b'\'') {
                    blank(&mut out, i, after + 1);
                    i = after + 1;
                } else {
                    i += 1;
                }
            } else {
                i += 1;
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8(out).unwrap()
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    /// `::`
    Sep,
    Punct(char),
}

/// Tokens with their byte offsets.
fn tokens(code: &str) -> Vec<(Tok, usize)> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_alphabetic() || c == b'_' || c >= 0x80 {
            let mut start = i;
            // A raw identifier (`r#move`) is the identifier.
            if code[i..].starts_with("r#")
                && b.get(i + 2)
                    .is_some_and(|c| c.is_ascii_alphabetic() || *c == b'_')
            {
                i += 2;
                start = i;
            }
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] >= 0x80) {
                i += 1;
            }
            out.push((Tok::Ident(code[start..i].to_owned()), start));
        } else if c.is_ascii_digit() {
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
        } else if c == b':' && b.get(i + 1) == Some(&b':') {
            out.push((Tok::Sep, i));
            i += 2;
        } else {
            out.push((Tok::Punct(c as char), i));
            i += 1;
        }
    }
    out
}

/// Whether an attribute's text (`cfg(test)`, `cfg(all(test, feature = ".."))`) makes its
/// item test-only.
fn is_test_cfg(attr: &str) -> bool {
    let a: String = attr.chars().filter(|c| !c.is_whitespace()).collect();
    a.starts_with("cfg(")
        && !a.contains("not(test")
        && a.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .any(|w| w == "test")
}

/// The end of the item that starts at `from`: after its first `;` at depth 0, or after the
/// braces its first `{` at depth 0 opens.
fn item_end(b: &[u8], from: usize) -> usize {
    let mut depth = 0i32;
    let mut i = from;
    while i < b.len() {
        match b[i] {
            b'(' | b'[' => depth += 1,
            b')' | b']' => depth -= 1,
            b';' if depth == 0 => return i + 1,
            b'{' if depth == 0 => {
                let mut d = 0;
                while i < b.len() {
                    match b[i] {
                        b'{' => d += 1,
                        b'}' => {
                            d -= 1;
                            if d == 0 {
                                return i + 1;
                            }
                        }
                        _ => {}
                    }
                    i += 1;
                }
                return b.len();
            }
            _ => {}
        }
        i += 1;
    }
    b.len()
}

/// One past the `]` that closes the `[` at `open`.
fn bracket_end(b: &[u8], open: usize) -> usize {
    let mut depth = 0;
    for (i, &c) in b.iter().enumerate().skip(open) {
        match c {
            b'[' => depth += 1,
            b']' => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
    }
    b.len()
}

/// Test-only items (`#[cfg(test)] mod tests { .. }`, `#[cfg(test)] fn ..`) blanked out.
fn blank_test_code(code: &str) -> String {
    let b = code.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    while let Some(n) = code[i..].find("#[") {
        let start = i + n;
        let close = bracket_end(b, start + 1);
        let attr = &code[start + 2..close - 1];
        if !is_test_cfg(attr) {
            i = start + 2;
            continue;
        }
        // Skip further attributes, then the item.
        let mut j = close;
        loop {
            while j < b.len() && b[j].is_ascii_whitespace() {
                j += 1;
            }
            if code[j..].starts_with("#[") {
                j = bracket_end(b, j + 1);
            } else {
                break;
            }
        }
        let end = item_end(b, j);
        for c in &mut out[start..end] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
        i = end;
    }
    String::from_utf8(out).unwrap()
}

/// The name after `as` at `t[*i..]`, if there is one (`*i` moves past it).
fn renamed(t: &[(Tok, usize)], i: &mut usize) -> Option<String> {
    if let Some((Tok::Ident(word), _)) = t.get(*i)
        && word == "as"
    {
        *i += 2;
        if let Some((Tok::Ident(name), _)) = t.get(*i - 1) {
            return Some(name.clone());
        }
    }
    None
}

/// Parses one use tree from `t[*i..]` with `prefix`, pushing its bindings.
fn use_tree(
    t: &[(Tok, usize)],
    i: &mut usize,
    prefix: &[String],
    out: &mut Vec<(Vec<String>, String)>,
) {
    let mut path = prefix.to_vec();
    if t.get(*i).map(|x| &x.0) == Some(&Tok::Sep) {
        *i += 1;
    }
    loop {
        match t.get(*i).map(|x| x.0.clone()) {
            Some(Tok::Ident(w))
                if w == "self" && !path.is_empty() && path.len() == prefix.len() =>
            {
                *i += 1;
                let name =
                    renamed(t, i).unwrap_or_else(|| path.last().cloned().unwrap_or_default());
                out.push((path, name));
                return;
            }
            Some(Tok::Ident(w)) => {
                path.push(w);
                *i += 1;
                if t.get(*i).map(|x| &x.0) == Some(&Tok::Sep) {
                    *i += 1;
                    continue;
                }
                let name =
                    renamed(t, i).unwrap_or_else(|| path.last().cloned().unwrap_or_default());
                out.push((path, name));
                return;
            }
            Some(Tok::Punct('*')) => {
                *i += 1;
                out.push((path, "*".to_owned()));
                return;
            }
            Some(Tok::Punct('{')) => {
                *i += 1;
                loop {
                    match t.get(*i).map(|x| &x.0) {
                        Some(Tok::Punct('}')) => {
                            *i += 1;
                            return;
                        }
                        Some(Tok::Punct(',')) => *i += 1,
                        None => return,
                        _ => {
                            let before = *i;
                            use_tree(t, i, &path, out);
                            if *i == before {
                                *i += 1;
                            }
                        }
                    }
                }
            }
            _ => return,
        }
    }
}

/// Line number (1-based) of byte offset `at`.
fn line_of(text: &str, at: usize) -> usize {
    text[..at].bytes().filter(|&c| c == b'\n').count() + 1
}

/// Whether the `use` at `toks[at]` is a re-export: `pub use`, `pub(crate) use`,
/// `pub(super) use`.
fn is_public(toks: &[(Tok, usize)], at: usize) -> bool {
    let pubword = Tok::Ident("pub".into());
    (at >= 1 && toks[at - 1].0 == pubword)
        || (at >= 4 && toks[at - 1].0 == Tok::Punct(')') && toks[at - 4].0 == pubword)
}

/// The path in code that starts at `toks[at]` (`crate::a::b`, `super::X`, `dispatch::run`)
/// and the index after it; `None` where no path starts (a lone name, a method's name).
fn path_at(toks: &[(Tok, usize)], at: usize) -> Option<(Vec<String>, usize)> {
    let Tok::Ident(first) = &toks[at].0 else {
        return None;
    };
    let after_sep = at >= 1 && matches!(toks[at - 1].0, Tok::Sep | Tok::Punct('.'));
    if after_sep || toks.get(at + 1).map(|x| &x.0) != Some(&Tok::Sep) {
        return None;
    }
    let mut path = vec![first.clone()];
    let mut next = at + 1;
    while toks.get(next).map(|x| &x.0) == Some(&Tok::Sep) {
        let Some((Tok::Ident(seg), _)) = toks.get(next + 1) else {
            break;
        };
        path.push(seg.clone());
        next += 2;
    }
    Some((path, next))
}

/// The file of child module `name` of the module in file `rel`.
fn child_file(files: &BTreeMap<String, String>, rel: &str, name: &str) -> String {
    let dir = if rel == "lib.rs" || rel.ends_with("/mod.rs") {
        Path::new(rel).parent().unwrap().to_path_buf()
    } else {
        Path::new(rel).with_extension("")
    };
    let flat = dir
        .join(format!("{name}.rs"))
        .to_string_lossy()
        .replace('\\', "/");
    let nested = dir
        .join(name)
        .join("mod.rs")
        .to_string_lossy()
        .replace('\\', "/");
    if files.contains_key(&flat) {
        flat
    } else {
        nested
    }
}

/// Reads module `path` from file `rel` (and its inline modules), then its child files.
fn read_module(files: &BTreeMap<String, String>, krate: &mut Crate, path: &[String], rel: &str) {
    let raw = files
        .get(rel)
        .unwrap_or_else(|| panic!("no file {rel} for module {path:?}"));
    let code = blank_test_code(&blank_comments_and_literals(raw));
    let toks = tokens(&code);

    // Inline module regions: (start, end, module path).
    let mut regions: Vec<(usize, usize, Vec<String>)> = vec![(0, code.len(), path.to_vec())];
    let module_at = |regions: &[(usize, usize, Vec<String>)], offset: usize| -> Vec<String> {
        regions
            .iter()
            .filter(|(start, end, _)| (*start..*end).contains(&offset))
            .max_by_key(|(_, _, module)| module.len())
            .map(|r| r.2.clone())
            .unwrap()
    };
    let mut child_files = Vec::new();
    rel.clone_into(&mut krate.modules.entry(path.to_vec()).or_default().file);

    let mut at = 0;
    while at < toks.len() {
        let (tok, offset) = &toks[at];
        let here = module_at(&regions, *offset);
        let module = krate.modules.get_mut(&here).unwrap();
        let name_after = |n: usize| match toks.get(at + n) {
            Some((Tok::Ident(name), _)) => Some(name.clone()),
            _ => None,
        };
        match tok {
            Tok::Ident(word) if word == "mod" => {
                if let Some(name) = name_after(1) {
                    module.children.insert(name.clone());
                    let child: Vec<String> = here.iter().cloned().chain([name.clone()]).collect();
                    match toks.get(at + 2) {
                        Some((Tok::Punct('{'), open)) => {
                            regions.push((*open, item_end(code.as_bytes(), *open), child.clone()));
                            rel.clone_into(&mut krate.modules.entry(child).or_default().file);
                        }
                        _ if here.len() == path.len() => child_files.push(name),
                        _ => panic!("{rel}: an inline module's `mod {name};` is not supported"),
                    }
                }
                at += 2;
            }
            Tok::Ident(word) if word == "use" => {
                let (public, line) = (is_public(&toks, at), line_of(&code, *offset));
                let mut bound = Vec::new();
                at += 1;
                use_tree(&toks, &mut at, &[], &mut bound);
                for (path, name) in bound {
                    module.imports.push(Import {
                        path,
                        name,
                        public,
                        line,
                    });
                }
            }
            Tok::Ident(word)
                if matches!(
                    word.as_str(),
                    "fn" | "struct" | "enum" | "trait" | "type" | "const" | "static" | "union"
                ) =>
            {
                module.defined.extend(name_after(1));
                at += 1;
            }
            Tok::Ident(word) if word == "macro_rules" => {
                module.defined.extend(name_after(2));
                at += 1;
            }
            _ => match path_at(&toks, at) {
                // A path in code: `crate::..`, `super::..`, `self::..`, `$crate::..` or a
                // name in scope followed by `::` (resolved later: a child module or an
                // import counts, anything else is outside or local).
                Some((path, next)) => {
                    let line = line_of(&code, *offset);
                    krate.references.push(Reference {
                        module: here,
                        path,
                        line,
                    });
                    at = next;
                }
                None => at += 1,
            },
        }
    }

    for name in child_files {
        let file = child_file(files, rel, &name);
        let child: Vec<String> = path.iter().cloned().chain([name]).collect();
        read_module(files, krate, &child, &file);
    }
}

// ---------------------------------------------------------------------------------------
// Resolving paths to the module that holds what they name.

/// `path` as written in module `at`, made absolute (from the crate root); `None` for a
/// path that leaves the crate or names something local that is not a module or import.
fn absolute(krate: &Crate, at: &[String], path: &[String]) -> Option<Vec<String>> {
    absolute_at(krate, at, path, 0)
}

fn absolute_at(krate: &Crate, at: &[String], path: &[String], depth: usize) -> Option<Vec<String>> {
    let first = path.first()?;
    if depth > 32 {
        return None;
    }
    match first.as_str() {
        "crate" => Some(path[1..].to_vec()),
        "self" => Some(at.iter().chain(&path[1..]).cloned().collect()),
        "super" => {
            let mut base = at.to_vec();
            let mut rest = path;
            while rest.first().map(String::as_str) == Some("super") {
                base.pop()?;
                rest = &rest[1..];
            }
            Some(base.into_iter().chain(rest.iter().cloned()).collect())
        }
        name => {
            let module = krate.modules.get(at)?;
            if module.children.contains(name) {
                return Some(at.iter().chain(path).cloned().collect());
            }
            // An import of a name in scope (not a bare `use other_crate;`).
            let import = module
                .imports
                .iter()
                .find(|i| i.name == name && i.path.len() > 1)?;
            let target = absolute_at(krate, at, &import.path, depth + 1)?;
            Some(
                target
                    .into_iter()
                    .chain(path[1..].iter().cloned())
                    .collect(),
            )
        }
    }
}

/// The module holding what the absolute `path` names (through re-exports and globs).
fn holder(krate: &Crate, path: &[String], depth: usize) -> Option<Vec<String>> {
    if depth > 32 {
        return None;
    }
    let mut at: Vec<String> = Vec::new();
    for (n, seg) in path.iter().enumerate() {
        let module = krate.modules.get(&at)?;
        let rest = &path[n + 1..];
        if module.children.contains(seg) {
            at.push(seg.clone());
            continue;
        }
        if let Some(import) = module.imports.iter().find(|i| &i.name == seg) {
            let target = absolute(krate, &at, &import.path)?;
            let full: Vec<String> = target.into_iter().chain(rest.iter().cloned()).collect();
            return holder(krate, &full, depth + 1);
        }
        if module.defined.contains(seg) {
            return Some(at);
        }
        for glob in module.imports.iter().filter(|i| i.name == "*") {
            let Some(target) = absolute(krate, &at, &glob.path) else {
                continue;
            };
            let Some(g) = krate.modules.get(&target) else {
                continue;
            };
            if g.children.contains(seg)
                || g.defined.contains(seg)
                || g.imports.iter().any(|i| &i.name == seg)
            {
                let full: Vec<String> = target
                    .into_iter()
                    .chain(path[n..].iter().cloned())
                    .collect();
                return holder(krate, &full, depth + 1);
            }
        }
        return Some(at);
    }
    Some(at)
}

/// Every edge `(from file, to file)` with its evidence.
fn edges(krate: &Crate) -> Evidence {
    let mut out: Evidence = BTreeMap::new();
    let mut add = |from: &[String], to: &[String], what: String| {
        let (Some(f), Some(t)) = (krate.modules.get(from), krate.modules.get(to)) else {
            return;
        };
        if f.file != t.file {
            out.entry((f.file.clone(), t.file.clone()))
                .or_default()
                .push(what);
        }
    };
    for (at, module) in &krate.modules {
        for import in &module.imports {
            let Some(abs) = absolute(krate, at, &import.path) else {
                continue;
            };
            let target = if import.name == "*" {
                Some(abs.clone())
            } else {
                holder(krate, &abs, 0)
            };
            let Some(target) = target else { continue };
            // A re-export of the module's own descendants is no edge.
            if import.public && target.len() > at.len() && target.starts_with(at) {
                continue;
            }
            let what = format!(
                "{}:{} use {}",
                module.file,
                import.line,
                import.path.join("::")
            );
            add(at, &target, what);
        }
    }
    for r in &krate.references {
        let Some(abs) = absolute(krate, &r.module, &r.path) else {
            continue;
        };
        let Some(target) = holder(krate, &abs, 0) else {
            continue;
        };
        let file = &krate.modules[&r.module].file;
        add(
            &r.module,
            &target,
            format!("{file}:{} {}", r.line, r.path.join("::")),
        );
    }
    out
}

/// Strongly connected sets of more than one node (Tarjan).
fn circles(nodes: &BTreeSet<String>, edges: &BTreeSet<(String, String)>) -> Vec<Vec<String>> {
    struct State<'a> {
        next: BTreeMap<&'a str, Vec<&'a str>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        count: usize,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        s.index.insert(v, s.count);
        s.low.insert(v, s.count);
        s.count += 1;
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in s.next.get(v).cloned().unwrap_or_default() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut set = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                set.push(w.to_owned());
                if w == v {
                    break;
                }
            }
            if set.len() > 1 {
                set.sort();
                s.out.push(set);
            }
        }
    }
    let mut s = State {
        next: BTreeMap::new(),
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        count: 0,
        out: Vec::new(),
    };
    for (a, b) in edges {
        s.next.entry(a.as_str()).or_default().push(b.as_str());
    }
    for v in nodes {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v.as_str());
        }
    }
    s.out.sort();
    s.out
}

/// Whether module `a` is a strict ancestor of module `b`.
fn is_ancestor(a: &[String], b: &[String]) -> bool {
    a.len() < b.len() && b.starts_with(a)
}

/// The top-level module of a file (`catalogue/dispatch.rs` is `catalogue`); `lib.rs` is
/// the root, `None`.
fn top_level(file: &str) -> Option<String> {
    if file == "lib.rs" {
        return None;
    }
    let first = file.split('/').next()?;
    Some(first.trim_end_matches(".rs").to_owned())
}

/// Every circle of the crate in `files` (paths relative to `src`, with their text), each
/// described with the edges inside it; empty when the layers run one way.
fn find_circles(files: &BTreeMap<String, String>) -> Vec<String> {
    let mut krate = Crate::default();
    read_module(files, &mut krate, &[], "lib.rs");
    let evidence = edges(&krate);
    let mut report = Vec::new();

    let describe = |set: &[String], of: &dyn Fn(&str) -> Option<String>| {
        let mut inside: BTreeMap<(String, String), Vec<&String>> = BTreeMap::new();
        for ((from, to), why) in &evidence {
            let (Some(a), Some(b)) = (of(from), of(to)) else {
                continue;
            };
            if a != b && set.contains(&a) && set.contains(&b) {
                inside.entry((a, b)).or_default().extend(why);
            }
        }
        let mut text = format!("circle: {}", set.join(", "));
        for ((a, b), why) in inside {
            let shown: Vec<&str> = why.iter().take(2).map(|w| w.as_str()).collect();
            let more = if why.len() > 2 {
                format!(" (+{} more)", why.len() - 2)
            } else {
                String::new()
            };
            write!(text, "\n  {a} -> {b}: {}{more}", shown.join("; ")).unwrap();
        }
        text
    };

    // The module path of each file (its outermost module: a file's inline modules share it).
    let mut module_of: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (path, m) in &krate.modules {
        module_of
            .entry(m.file.clone())
            .or_insert_with(|| path.clone());
    }

    // Top-level modules.
    let top_nodes: BTreeSet<String> = krate
        .modules
        .values()
        .filter_map(|m| top_level(&m.file))
        .collect();
    let top_edges: BTreeSet<(String, String)> = evidence
        .keys()
        .filter_map(|(a, b)| Some((top_level(a)?, top_level(b)?)))
        .filter(|(a, b)| a != b)
        .collect();
    for set in circles(&top_nodes, &top_edges) {
        report.push(format!(
            "between top-level modules: {}",
            describe(&set, &top_level)
        ));
    }

    // Files inside each top-level module.
    for top in &top_nodes {
        let inside = |f: &str| top_level(f).as_deref() == Some(top.as_str());
        let nodes: BTreeSet<String> = krate
            .modules
            .values()
            .map(|m| m.file.clone())
            .filter(|f| inside(f))
            .collect();
        // A file using what an ancestor defines is part of that ancestor split out.
        let file_edges: BTreeSet<(String, String)> = evidence
            .keys()
            .filter(|(a, b)| inside(a) && inside(b) && !is_ancestor(&module_of[b], &module_of[a]))
            .cloned()
            .collect();
        for set in circles(&nodes, &file_edges) {
            report.push(format!(
                "inside `{top}`: {}",
                describe(&set, &|f| Some(f.to_owned()))
            ));
        }
    }
    report
}

/// Every `.rs` file under `dir`, keyed by its path relative to `root`.
fn read_tree(root: &Path, dir: &Path, out: &mut BTreeMap<String, String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            read_tree(root, &path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let rel = path
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            out.insert(rel, std::fs::read_to_string(&path).unwrap());
        }
    }
}

#[test]
fn the_library_has_no_import_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = BTreeMap::new();
    read_tree(&src, &src, &mut files);
    let found = find_circles(&files);
    assert!(
        found.is_empty(),
        "{} import circle(s) in crates/robobus/src (see tests/layers.rs for the rule):\n\n{}",
        found.len(),
        found.join("\n\n")
    );
}

// ---------------------------------------------------------------------------------------
// The rule itself, on small crates.

fn krate(files: &[(&str, &str)]) -> BTreeMap<String, String> {
    files
        .iter()
        .map(|(p, t)| ((*p).to_owned(), (*t).to_owned()))
        .collect()
}

#[test]
fn two_top_level_modules_that_use_each_other_are_a_circle_named_with_its_lines() {
    let found = find_circles(&krate(&[
        ("lib.rs", "pub mod error;\npub mod ops;\n"),
        ("error.rs", "use crate::ops::OpError;\npub enum Kind {}\n"),
        (
            "ops.rs",
            "pub struct OpError;\nfn f() -> crate::error::Kind { todo!() }\n",
        ),
    ]));
    assert_eq!(
        found,
        ["between top-level modules: circle: error, ops\n  \
          error -> ops: error.rs:1 use crate::ops::OpError\n  \
          ops -> error: ops.rs:2 crate::error::Kind"]
    );
}

#[test]
fn a_path_through_a_root_reexport_reaches_the_file_that_defines_it() {
    // `crate::Kind` is error.rs's; `ops::run` is what error.rs calls: a circle.
    let found = find_circles(&krate(&[
        (
            "lib.rs",
            "pub mod error;\npub mod ops;\npub use error::Kind;\n",
        ),
        (
            "error.rs",
            "pub enum Kind {}\nfn f() { crate::ops::run(); }\n",
        ),
        (
            "ops/mod.rs",
            "mod inner;\npub use inner::run;\nfn g(_: crate::Kind) {}\n",
        ),
        ("ops/inner.rs", "pub fn run() {}\n"),
    ]));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].starts_with("between top-level modules: circle: error, ops"),
        "{found:?}"
    );
    assert!(
        found[0].contains("error -> ops: error.rs:2 crate::ops::run"),
        "{found:?}"
    );
}

#[test]
fn a_parent_and_its_children_may_use_each_other_but_siblings_may_not() {
    let files = [
        ("lib.rs", "pub mod cat;\n"),
        (
            "cat/mod.rs",
            "mod dispatch;\nmod plan;\npub use dispatch::run;\npub struct Request;\n\
             impl Request { pub fn go(&self) { dispatch::run(self); } }\n",
        ),
        (
            "cat/dispatch.rs",
            "use super::Request;\npub fn run(_: &Request) {}\n",
        ),
        ("cat/plan.rs", "pub struct Plan;\n"),
    ];
    assert_eq!(find_circles(&krate(&files)), Vec::<String>::new());
    let mut files = files.to_vec();
    files[2].1 = "use super::Request;\nuse super::plan::Plan;\npub fn run(_: &Request) -> Option<Plan> { None }\n";
    files[3].1 = "pub struct Plan;\nfn f() { super::run(&super::Request); }\n";
    let found = find_circles(&krate(&files));
    assert_eq!(
        found,
        ["inside `cat`: circle: cat/dispatch.rs, cat/plan.rs\n  \
          cat/dispatch.rs -> cat/plan.rs: cat/dispatch.rs:2 use super::plan::Plan\n  \
          cat/plan.rs -> cat/dispatch.rs: cat/plan.rs:2 super::run"]
    );
}

#[test]
fn test_code_comments_and_strings_make_no_edge() {
    let found = find_circles(&krate(&[
        ("lib.rs", "pub mod a;\npub mod b;\n"),
        ("a.rs", "pub fn f() { crate::b::g() }\n"),
        (
            "b.rs",
            "pub fn g() {}\n/// See [`crate::a::f`].\n// crate::a::f\n\
             const S: &str = \"crate::a::f\";\nconst R: &str = r#\"crate::a::f\"#;\n\
             #[cfg(test)]\nmod tests {\n    use crate::a::f;\n}\n\
             #[cfg(all(test, feature = \"sim\"))]\nfn t() { crate::a::f() }\n",
        ),
    ]));
    assert_eq!(found, Vec::<String>::new());
}

#[test]
fn a_raw_identifier_names_its_module_file() {
    let found = find_circles(&krate(&[
        ("lib.rs", "pub mod a;\npub mod b;\n"),
        ("a/mod.rs", "mod r#move;\npub use r#move::Move;\n"),
        ("a/move.rs", "pub struct Move;\nfn f() { crate::b::g() }\n"),
        ("b.rs", "pub fn g() {}\nfn h(_: crate::a::Move) {}\n"),
    ]));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("a -> b: a/move.rs:2 crate::b::g"),
        "{found:?}"
    );
    assert!(
        found[0].contains("b -> a: b.rs:2 crate::a::Move"),
        "{found:?}"
    );
}

#[test]
fn a_glob_reexport_is_followed_to_the_file_that_defines_the_name() {
    // ops::whj re-exports checks::* ; robot uses crate::ops::whj::check, and checks uses
    // robot: the circle is robot <-> ops (through ops/whj/checks.rs).
    let found = find_circles(&krate(&[
        ("lib.rs", "pub mod ops;\npub mod robot;\n"),
        ("ops/mod.rs", "pub mod whj;\n"),
        ("ops/whj.rs", "mod checks;\npub use checks::*;\n"),
        (
            "ops/whj/checks.rs",
            "pub fn check(_: crate::robot::Robot) {}\n",
        ),
        (
            "robot.rs",
            "pub struct Robot;\nfn f() { crate::ops::whj::check(Robot) }\n",
        ),
    ]));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("robot -> ops: robot.rs:2 crate::ops::whj::check"),
        "{found:?}"
    );
}
