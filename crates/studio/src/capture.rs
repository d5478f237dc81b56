//! The studio's private capture folder: made fresh (never adopted) with an unpredictable
//! name, only this user's (mode 0700 on Unix; on Windows the ACL it inherits from the
//! user's own temporary folder, `%LOCALAPPDATA%\Temp`), its files read without following a
//! symbolic link, and only what the studio made removed when it stops.

use std::fs::File;
use std::io;
#[cfg(unix)]
use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _};
use std::path::{Path, PathBuf};

/// How many names are tried before giving up (each is 128 random bits: a clash means
/// someone keeps making folders with the prefix).
const ATTEMPTS: usize = 8;

/// A folder only this user can enter, made for one studio.
#[derive(Debug)]
pub struct CaptureDir {
    path: PathBuf,
}

impl CaptureDir {
    /// Makes `PARENT/robobus-studio-RANDOM` with mode 0700 (on Windows: with the ACL of
    /// `PARENT`, so `PARENT` must be the user's own folder, as [`std::env::temp_dir`] is
    /// there). A name that exists already (a folder, a symbolic link or a junction someone
    /// made) is never used: another name is drawn.
    pub fn create(parent: &Path) -> io::Result<Self> {
        let mut last = None;
        for _ in 0..ATTEMPTS {
            let mut bytes = [0u8; 16];
            getrandom::fill(&mut bytes).map_err(io::Error::other)?;
            let name = bytes
                .iter()
                .fold(String::from("robobus-studio-"), |mut s, b| {
                    use std::fmt::Write as _;
                    let _ = write!(s, "{b:02x}");
                    s
                });
            let path = parent.join(name);
            // `create`, not `create_all`: it fails on anything already there, a symbolic
            // link too, instead of adopting it.
            match private_dir_builder().create(&path) {
                Ok(()) => return Ok(Self { path }),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.unwrap_or_else(|| io::Error::other("no free name")))
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Removes the files the studio made (`made`, each only if it is in this folder; a
    /// symbolic link put in a file's place is removed, its target never touched), then
    /// the folder if nothing else is left in it. Returns what was left behind.
    pub fn remove(self, made: &[PathBuf]) -> Vec<PathBuf> {
        let mut left = Vec::new();
        for file in made {
            if file.parent() != Some(self.path.as_path()) {
                continue;
            }
            match std::fs::symlink_metadata(file) {
                Ok(m) if m.is_file() || m.file_type().is_symlink() => {
                    if std::fs::remove_file(file).is_err() {
                        left.push(file.clone());
                    }
                }
                Ok(_) => left.push(file.clone()),
                Err(_) => {}
            }
        }
        // Not `remove_dir_all`: anything the studio did not make stays, and so does the
        // folder holding it.
        if std::fs::remove_dir(&self.path).is_err() && self.path.exists() {
            left.push(self.path);
        }
        left
    }
}

/// A builder of folders only this user can enter: mode 0700.
#[cfg(unix)]
fn private_dir_builder() -> std::fs::DirBuilder {
    let mut builder = std::fs::DirBuilder::new();
    builder.mode(0o700);
    builder
}

/// A builder of folders only this user can enter: the folder inherits the ACL of its
/// parent, the user's own folder.
#[cfg(not(unix))]
fn private_dir_builder() -> std::fs::DirBuilder {
    std::fs::DirBuilder::new()
}

/// Opens a capture file for reading, refusing a symbolic link (or anything but a regular
/// file) in its place: the file opened is the one looked at, checked by its device and
/// inode after opening.
#[cfg(unix)]
pub(crate) fn open_regular(path: &Path) -> io::Result<File> {
    let before = std::fs::symlink_metadata(path)?;
    if !before.is_file() {
        return Err(not_followed());
    }
    let file = File::open(path)?;
    let opened = file.metadata()?;
    if (opened.dev(), opened.ino()) != (before.dev(), before.ino()) {
        return Err(replaced());
    }
    Ok(file)
}

/// Opens a capture file for reading, refusing a symbolic link, a junction (any reparse
/// point) or anything but a regular file in its place. The file is opened with
/// `FILE_FLAG_OPEN_REPARSE_POINT`, so a link is opened itself instead of followed, and the
/// opened handle's own attributes are checked: what is read is what was checked, with no
/// window between a look by path and the open.
#[cfg(windows)]
pub(crate) fn open_regular(path: &Path) -> io::Result<File> {
    use std::os::windows::fs::{MetadataExt as _, OpenOptionsExt as _};
    /// `FILE_FLAG_OPEN_REPARSE_POINT` (winbase.h).
    const OPEN_REPARSE_POINT: u32 = 0x0020_0000;
    /// `FILE_ATTRIBUTE_REPARSE_POINT` (winnt.h).
    const ATTRIBUTE_REPARSE_POINT: u32 = 0x0400;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(OPEN_REPARSE_POINT)
        .open(path)?;
    let opened = file.metadata()?;
    if !opened.is_file() || opened.file_attributes() & ATTRIBUTE_REPARSE_POINT != 0 {
        return Err(not_followed());
    }
    Ok(file)
}

fn not_followed() -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        "not a regular file (a symbolic link or another kind of file is not followed)",
    )
}

#[cfg(unix)]
fn replaced() -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        "the file was replaced while it was opened (not followed)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn made_private_and_fresh_and_only_its_own_files_removed() {
        let parent = tempfile::tempdir().unwrap();
        let a = CaptureDir::create(parent.path()).unwrap();
        let b = CaptureDir::create(parent.path()).unwrap();
        assert_ne!(a.path(), b.path());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(a.path()).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o700);
        }
        let mine = a.path().join("sim-wck.log");
        std::fs::write(&mine, "x").unwrap();
        let theirs = a.path().join("theirs");
        std::fs::write(&theirs, "y").unwrap();
        let outside = parent.path().join("outside");
        std::fs::write(&outside, "z").unwrap();
        let dir = a.path().to_owned();
        let left = a.remove(&[mine.clone(), outside.clone()]);
        assert!(!mine.exists());
        assert!(theirs.exists() && outside.exists());
        assert_eq!(left, vec![dir]);
        let dir = b.path().to_owned();
        assert!(b.remove(&[]).is_empty());
        assert!(!dir.exists());
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_is_not_opened() {
        let parent = tempfile::tempdir().unwrap();
        let target = parent.path().join("secret");
        std::fs::write(&target, "secret").unwrap();
        let link = parent.path().join("capture.log");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        assert_eq!(
            open_regular(&link).unwrap_err().kind(),
            io::ErrorKind::InvalidData
        );
        assert!(open_regular(&target).is_ok());
    }

    #[test]
    fn a_folder_is_not_opened_a_regular_file_is() {
        let parent = tempfile::tempdir().unwrap();
        let file = parent.path().join("capture.log");
        std::fs::write(&file, "x").unwrap();
        assert!(open_regular(parent.path()).is_err());
        assert!(open_regular(&file).is_ok());
    }
}
