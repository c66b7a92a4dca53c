"""`srlab study`: trainer studies from the shell, on the database (docs/studies.md).

`create`, `add`, `status`, `forget` and `export` each open the store as `srlab export`
does (`--url`, else SRLAB_DATABASE_URL). Input is checked with the API's own schemas, so
the command refuses what the API refuses, and before anything is stored.
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from rich import box
from rich.console import Console
from rich.table import Table

from server.cli.common import (
    UsageError,
    check_out_folder,
    counted,
    positive_int,
    print_table,
    progress_bar,
)

if TYPE_CHECKING:
    from pydantic import BaseModel, ValidationError

    from core.studies import StudyRepository, StudySpec
    from server.persistence import SqlAlchemyRunStore

FLAGS = {
    "name": "NAME",
    "conditions": "--conditions",
    "assignment": "--assignment",
    "budget": "--episodes/--seconds",
    "consent_text": "--consent-file",
    "consent_version": "--consent-version",
    "questionnaire": "--questionnaire",
    "completion_code": "--completion-code",
    "redirect_url": "--redirect",
    "external_ids": "--ids",
    "count": "--count",
}
"""The flag that gave each schema field, for messages that name what to change."""
LINK_COLUMNS = ("pseudonym", "external_id", "token", "link")
"""`srlab study add --out`'s CSV columns."""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `study` command, its actions and their arguments."""
    parser = sub.add_parser(
        "study",
        help="trainer studies: create one, invite participants, watch progress, export it",
        description="Trainer studies on the database (docs/studies.md): each participant "
        "trains a robot of their own through their link.",
    )
    actions = parser.add_subparsers(dest="study_command", required=True, metavar="ACTION")

    create = actions.add_parser(
        "create",
        help="create a study",
        description="Create a study: the conditions to assign, a budget per participant, the "
        "consent text and its version, and what a participant gets when done.",
    )
    create.add_argument("name", metavar="NAME", help="the study's name (letters, digits, ._-)")
    create.add_argument(
        "--conditions",
        required=True,
        help="the conditions to assign, comma-separated, each once (e.g. kp,trainer)",
    )
    create.add_argument(
        "--assignment",
        choices=["balanced", "fixed"],
        default="balanced",
        help="balanced: the condition with the fewest participants so far (default); "
        "fixed: the first condition for everyone",
    )
    budget = create.add_mutually_exclusive_group(required=True)
    budget.add_argument(
        "--episodes", type=positive_int, metavar="N", help="each participant's budget: episodes"
    )
    budget.add_argument(
        "--seconds", type=float, metavar="S", help="each participant's budget: seconds of their run"
    )
    create.add_argument(
        "--consent-file", required=True, type=Path, metavar="FILE", help="the consent text"
    )
    create.add_argument(
        "--consent-version", required=True, metavar="V", help="the consent text's version"
    )
    create.add_argument(
        "--questionnaire",
        type=Path,
        metavar="FILE",
        help="short questions shown after consent, one a line",
    )
    done = create.add_mutually_exclusive_group(required=True)
    done.add_argument("--completion-code", metavar="C", help="shown when the budget is spent")
    done.add_argument("--redirect", metavar="URL", help="where a finished participant goes")
    _common(create)

    add = actions.add_parser(
        "add",
        help="invite participants: each one's link and token, shown once",
        description="Invite participants by recruiter's id (one a line in --ids) or --count "
        "anonymous ones. Each one's token is shown once (only its digest is stored): printed, "
        "or written to a new CSV file with --out.",
    )
    add.add_argument("name", metavar="NAME", help="the study")
    who = add.add_mutually_exclusive_group(required=True)
    who.add_argument("--ids", type=Path, metavar="FILE", help="recruiters' ids, one a line")
    who.add_argument("--count", type=positive_int, metavar="N", help="N anonymous participants")
    add.add_argument(
        "--out", type=Path, metavar="CSV", help="write the links here (a new file) instead"
    )
    add.add_argument(
        "--service",
        metavar="URL",
        help="the service's address, for the links (default http://SRLAB_HOST:SRLAB_PORT)",
    )
    _common(add)

    status = actions.add_parser("status", help="a study's progress: participants per status")
    status.add_argument("name", metavar="NAME", help="the study")
    _common(status)

    forget = actions.add_parser(
        "forget",
        help="delete a study's recruiters' ids (pseudonyms, runs and rewards stay)",
        description="Delete the mapping from recruiters' ids to pseudonyms: the study's data "
        "stays and no longer leads back to a person. It cannot be undone: add --yes.",
    )
    forget.add_argument("name", metavar="NAME", help="the study")
    forget.add_argument("--yes", action="store_true", help="yes, delete them")
    _common(forget)

    export = actions.add_parser(
        "export",
        help="write a study's data as files for analysis",
        description="Write each participant's run export into DIR/<pseudonym>/, every "
        "participant's rewards and episodes into DIR/rewards.* and DIR/episodes.*, and "
        "DIR/study.json (docs/export.md). No recruiter's id is written.",
    )
    export.add_argument("name", metavar="STUDY", help="the study")
    export.add_argument("--out", required=True, type=Path, metavar="DIR", help="the folder")
    export.add_argument("--minari", action="store_true", help="also a Minari dataset per run")
    export.add_argument(
        "--force",
        action="store_true",
        help="write into DIR even if it holds files (the study's files there are replaced)",
    )
    export.add_argument("--quiet", action="store_true", help="no progress display")
    _common(export)
    parser.set_defaults(handler=study)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")


def study(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab study ACTION`."""
    action = {
        "create": _create,
        "add": _add,
        "status": _status,
        "forget": _forget,
        "export": _export,
    }[args.study_command]
    return action(args, stdout, stderr)


@contextmanager
def _stores(url: str | None) -> Iterator[tuple[SqlAlchemyRunStore, StudyRepository]]:
    from server.cli.db import open_store
    from server.persistence import make_sessionmaker
    from server.persistence.studies import SqlAlchemyStudyRepository

    runs, engine = open_store(url)
    try:
        yield runs, SqlAlchemyStudyRepository(make_sessionmaker(engine))
    finally:
        engine.dispose()


def _message(error: ValidationError, flags: dict[str, str]) -> str:
    """A schema's refusal, each field named by its flag, with the value it refused.

    A union's alternatives each refuse (the budget: episodes or seconds): a missing or an
    extra key is the other alternative's complaint, left out when the field has another.
    """
    found: dict[str, list[str]] = {}
    for e in error.errors():
        field = str(e["loc"][0]) if e["loc"] else ""
        given = e.get("input")
        shown = f" (got {given!r})" if isinstance(given, str | int | float) else ""
        found.setdefault(field, []).append(
            f"{e['msg']}{shown}" if e["type"] not in ("missing", "extra_forbidden") else ""
        )
    parts = []
    for field, messages in found.items():
        said = [m for m in dict.fromkeys(messages) if m] or ["not a valid value"]
        parts.append(f"{flags.get(field, field)}: {'; '.join(said)}")
    return "; ".join(parts)


def _budget(spec: StudySpec) -> str:
    """A participant's budget as the organiser reads it: "1 episode", "5 episodes", "600 s"."""
    if spec.budget_episodes is None:
        return f"{spec.budget_s:g} s"
    return counted(spec.budget_episodes, "episode")


def _checked(
    model: type[BaseModel], values: dict[str, Any], flags: dict[str, str] | None = None
) -> Any:
    from pydantic import ValidationError

    try:
        return model.model_validate(values)
    except ValidationError as e:
        raise UsageError(_message(e, FLAGS | (flags or {}))) from None


def _read(path: Path, flag: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UsageError(f"{flag} {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"{flag} {path}: cannot read it as UTF-8 text ({e})") from None


def _lines(path: Path, flag: str) -> list[str]:
    """A file's lines, trimmed, blank ones left out."""
    return [line.strip() for line in _read(path, flag).splitlines() if line.strip()]


def _create(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from server.schemas.studies import StudyCreate
    from server.services.studies import new_study

    budget = {"episodes": args.episodes} if args.episodes is not None else {}
    if args.seconds is not None:
        budget = {"seconds": args.seconds}
    values: dict[str, Any] = {
        "name": args.name,
        "conditions": [c.strip() for c in args.conditions.split(",")],
        "assignment": args.assignment,
        "budget": budget,
        "consent_text": _read(args.consent_file, "--consent-file").strip(),
        "consent_version": args.consent_version,
        "questionnaire": (
            [] if args.questionnaire is None else _lines(args.questionnaire, "--questionnaire")
        ),
        "completion_code": args.completion_code,
        "redirect_url": args.redirect,
    }
    body = _checked(StudyCreate, values, {"budget": f"--{next(iter(budget))}"})
    with _stores(args.url) as (_, studies):
        made = new_study(studies, body)
    spec = made.spec
    budget_text = _budget(spec)
    Console(file=stdout).print(
        f"study {spec.name} created: conditions {', '.join(spec.conditions)} "
        f"({spec.assignment.value}), {budget_text} each, consent version "
        f"{spec.consent_version}; invite people with: srlab study add {spec.name}",
        highlight=False,
        soft_wrap=True,
    )
    return 0


def _service(given: str | None) -> str:
    if given is not None:
        if not given.startswith(("http://", "https://")):
            raise UsageError(f"--service {given}: an http:// or https:// address")
        return given
    from server.config import Settings

    settings = Settings()
    return f"http://{settings.host}:{settings.port}"


def _add(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from server.schemas.studies import ParticipantsAnonymous, ParticipantsNamed
    from server.services.studies import invite

    ids: list[str | None]
    if args.ids is not None:
        named = _checked(ParticipantsNamed, {"external_ids": _lines(args.ids, "--ids")})
        ids = list(named.external_ids)
    else:
        ids = [None] * _checked(ParticipantsAnonymous, {"count": args.count}).count
    service = _service(args.service)
    out: Path | None = args.out
    if out is not None and out.exists():
        raise UsageError(f"--out {out} exists: the tokens go into a new file only")
    with _stores(args.url) as (_, studies):
        studies.get(args.name)  # an unknown study before the file is made
        # Opened before the participants are stored: their tokens exist only in this answer.
        with _links_file(out) as f:
            made = invite(studies, args.name, ids, service)
            rows = [(i.participant.pseudonym, i.external_id or "", i.token, i.link) for i in made]
            if f is not None:
                writer = csv.writer(f)
                writer.writerow(LINK_COLUMNS)
                writer.writerows(rows)
    console = Console(file=stdout)
    if out is not None:
        console.print(
            f"invited {len(rows)} participants to study {args.name}: their links and tokens "
            f"are in {out} (shown nowhere else)",
            highlight=False,
            soft_wrap=True,
        )
        return 0
    for pseudonym, external, token, link in rows:
        who = external or pseudonym[:12]
        console.print(f"{who}  {link}  token {token}", highlight=False, soft_wrap=True)
    console.print(
        f"invited {len(rows)} participants to study {args.name}: each link and token is "
        "shown only here",
        highlight=False,
        soft_wrap=True,
    )
    return 0


@contextmanager
def _links_file(out: Path | None) -> Iterator[IO[str] | None]:
    """The new CSV file for the links (None: print them), removed if nothing was stored."""
    if out is None:
        yield None
        return
    try:
        f = out.open("x", encoding="utf-8", newline="")
    except OSError as e:
        raise UsageError(f"--out {out}: cannot make it ({e.strerror})") from None
    try:
        with f:
            yield f
    except BaseException:
        out.unlink(missing_ok=True)
        raise


def _status(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from core.studies import ParticipantStatus
    from server.services.studies import settle_stored

    with _stores(args.url) as (runs, studies):
        participants = settle_stored(studies, runs, args.name)
        found = studies.get(args.name)
    spec = found.spec
    budget = _budget(spec)
    Console(file=stdout).print(
        f"study {spec.name}: conditions {', '.join(spec.conditions)} ({spec.assignment.value}),"
        f" {budget} each, consent version {spec.consent_version}",
        highlight=False,
        soft_wrap=True,
    )
    table = Table(box=box.SIMPLE_HEAD)
    table.add_column("status")
    for condition in spec.conditions:
        table.add_column(condition, justify="right")
    table.add_column("all", justify="right")
    for status in ParticipantStatus:
        at = [p for p in participants if p.status is status]
        by = [sum(p.condition == c for p in at) for c in spec.conditions]
        table.add_row(status.value, *(str(n) if n else "-" for n in by), str(len(at)))
    table.add_row(
        "all",
        *(str(sum(p.condition == c for p in participants)) for c in spec.conditions),
        str(len(participants)),
        style="bold",
    )
    print_table(stdout, table)
    return 0


def _forget(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    if not args.yes:
        raise UsageError(f"forget deletes study {args.name}'s recruiters' ids for good: add --yes")
    with _stores(args.url) as (_, studies):
        deleted = studies.delete_identities(args.name)
    Console(file=stdout).print(
        f"study {args.name}: deleted {deleted} recruiters' ids; pseudonyms, runs and rewards stay",
        highlight=False,
        soft_wrap=True,
    )
    return 0


def _export(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from server.export import export_study
    from server.export.dataset import require_minari
    from server.export.study import clear
    from server.services.studies import settle_stored

    out: Path = args.out
    check_out_folder(out, args.force)
    if args.minari:
        require_minari()
    with _stores(args.url) as (runs, studies):
        # An unknown study before writing; each status as stored runs say (`status`).
        participants = settle_stored(studies, runs, args.name)
        if out.is_dir():
            clear(out, participants)
        err = Console(file=stderr, stderr=True)
        progress, bar = progress_bar(
            err, "[bold]study export[/]", len(participants), quiet=args.quiet
        )
        with progress:
            done = export_study(
                runs,
                studies,
                args.name,
                out,
                minari=args.minari,
                progress=lambda *_: progress.advance(bar),
            )
    Console(file=stdout).print(
        f"study {done.study}: {counted(done.participants, 'participant')}, "
        f"{counted(done.runs, 'run')}, {counted(done.rewards, 'reward')}, "
        f"{counted(done.episodes, 'episode')}, {counted(done.answers, 'answer')} -> {out}",
        highlight=False,
        soft_wrap=True,
    )
    return 0
