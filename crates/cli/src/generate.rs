//! `robobus completions SHELL` and `robobus man`: shell completions and man pages,
//! generated from the clap definitions (so they never drift from `--help`).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::CommandFactory as _;
use clap_complete::Shell;

/// Options of `robobus completions`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Install, for example:
  robobus completions bash > ~/.local/share/bash-completion/completions/robobus
  robobus completions zsh  > ~/.zfunc/_robobus      # with fpath+=(~/.zfunc) in .zshrc
  robobus completions fish > ~/.config/fish/completions/robobus.fish")]
pub(crate) struct CompletionArgs {
    /// The shell.
    #[arg(value_enum)]
    shell: Shell,
}

/// Options of `robobus man`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Writes robobus.1 and one page per subcommand (robobus-wck.1, robobus-wck-move.1, ...).
View one with `man -l DIR/robobus.1`; install with `cp DIR/*.1 /usr/local/share/man/man1/`.")]
pub(crate) struct ManArgs {
    /// Directory to write the pages to (created if missing). Without it, robobus.1 goes to
    /// stdout.
    #[arg(short, long, value_name = "DIR")]
    output: Option<PathBuf>,
}

/// Prints the completion script.
pub(crate) fn completions(args: &CompletionArgs) -> anyhow::Result<()> {
    let mut cmd = crate::Cli::command();
    let mut buf = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "robobus", &mut buf);
    crate::output::print(&String::from_utf8_lossy(&buf))
}

/// Writes the man pages.
pub(crate) fn man(args: &ManArgs) -> anyhow::Result<()> {
    let mut cmd = crate::Cli::command();
    cmd.build();
    match &args.output {
        None => {
            let mut buf = Vec::new();
            clap_mangen::Man::new(cmd).render(&mut buf)?;
            crate::output::print(&String::from_utf8_lossy(&buf))
        }
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let mut written = Vec::new();
            write_pages(&cmd, "robobus", dir, &mut written)?;
            let mut err = std::io::stderr().lock();
            let _ = writeln!(
                err,
                "wrote {} man pages to {}",
                written.len(),
                dir.display()
            );
            Ok(())
        }
    }
}

/// Writes the page of `cmd` as `name.1` and recurses into its subcommands.
fn write_pages(
    cmd: &clap::Command,
    name: &str,
    dir: &Path,
    written: &mut Vec<PathBuf>,
) -> anyhow::Result<()> {
    let page = cmd.clone();
    let path = dir.join(format!("{name}.1"));
    let mut buf = Vec::new();
    clap_mangen::Man::new(page).render(&mut buf)?;
    std::fs::write(&path, buf).with_context(|| format!("cannot write {}", path.display()))?;
    written.push(path);
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        write_pages(sub, &format!("{name}-{}", sub.get_name()), dir, written)?;
    }
    Ok(())
}
