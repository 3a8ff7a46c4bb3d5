//! The command line with no optional flag is the library's recipe, per role.
use super::TrainCommand;
use crate::cli::{Cli, Command};
use crate::train::recipe::{DpRun, StudentRun, TeacherRun, TrainConfig};
use clap::Parser;
use std::path::PathBuf;

/// The train command of a command line (words split at white space).
fn parse(line: &str) -> TrainCommand {
    match Cli::try_parse_from(line.split_whitespace())
        .expect("valid command line")
        .command
    {
        Command::Train(cmd) => cmd,
        other => panic!("not a train command: {other:?}"),
    }
}

fn paths(mut cfg: TrainConfig, data: &str, out: &str) -> TrainConfig {
    (cfg.data, cfg.out) = (PathBuf::from(data), PathBuf::from(out));
    cfg
}

#[test]
fn bare_teacher_command_is_the_teacher_recipe() {
    let TrainCommand::Teacher(args) = parse("frmd train teacher --data d --out o") else {
        panic!("teacher")
    };
    let run = TeacherRun::from(args);
    let expected = TeacherRun {
        train: paths(TrainConfig::teacher_recipe(), "d", "o"),
        ..TeacherRun::default()
    };
    assert_eq!(run, expected);
    assert!(run.auto_scale_basis);
    assert_eq!(
        (run.train.steps, run.train.lr, run.train.warmup),
        (20_000, 1e-3, 500)
    );
}

#[test]
fn bare_student_and_dp_commands_are_their_recipes() {
    let TrainCommand::Student(args) = parse("frmd train student --teacher t --data d --out o")
    else {
        panic!("student")
    };
    let run = StudentRun::from(args);
    assert_eq!(
        run,
        StudentRun {
            train: paths(TrainConfig::student_recipe(), "d", "o"),
            teacher: PathBuf::from("t"),
            ..StudentRun::default()
        }
    );
    assert_eq!(
        (run.train.steps, run.train.lr, run.train.warmup),
        (3_000, 1e-4, 100)
    );

    let TrainCommand::Dp(args) = parse("frmd train dp --data d --out o") else {
        panic!("dp")
    };
    let run = DpRun::from(args);
    assert_eq!(
        run,
        DpRun {
            train: paths(TrainConfig::dp_recipe(), "d", "o"),
            ..DpRun::default()
        }
    );
}

#[test]
fn schedule_flags_override_the_recipe() {
    let TrainCommand::Teacher(args) = parse("frmd train teacher --data d --out o --steps 7 --lr 0.5 --warmup 2 --auto-scale-basis false") else {
        panic!("teacher")
    };
    let run = TeacherRun::from(args);
    assert_eq!(
        (
            run.train.steps,
            run.train.lr,
            run.train.warmup,
            run.auto_scale_basis
        ),
        (7, 0.5, 2, false)
    );
}
