"""Trainer studies, their participants, and the id to pseudonym mapping apart.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-08 10:00:00.000000

A study's participants are stored by pseudonym (an HMAC of the study's secret and the
recruiter's id) and by their token's SHA-256 only; the recruiter's ids sit in
`participant_identities`, which can be deleted without touching the rest.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | Sequence[str] | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _created() -> sa.Column[sa.DateTime]:
    return sa.Column(
        "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
    )


def upgrade() -> None:
    op.create_table(
        "studies",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("conditions", sa.JSON(), nullable=False),
        sa.Column("assignment", sa.String(length=20), nullable=False),
        sa.Column("budget_episodes", sa.Integer(), nullable=True),
        sa.Column("budget_s", sa.Double(), nullable=True),
        sa.Column("consent_text", sa.Text(), nullable=False),
        sa.Column("consent_version", sa.String(length=100), nullable=False),
        sa.Column("questionnaire", sa.JSON(), nullable=False),
        sa.Column("completion_code", sa.String(length=100), nullable=True),
        sa.Column("redirect_url", sa.Text(), nullable=True),
        sa.Column("secret", sa.String(length=64), nullable=False),
        _created(),
        sa.CheckConstraint(
            "assignment IN ('balanced', 'fixed')", name=op.f("ck_studies_assignment")
        ),
        sa.CheckConstraint(
            "(budget_episodes IS NULL) <> (budget_s IS NULL)", name=op.f("ck_studies_one_budget")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_studies")),
        sa.UniqueConstraint("name", name=op.f("uq_studies_name")),
    )
    op.create_table(
        "participants",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("pseudonym", sa.String(length=64), nullable=False),
        sa.Column("token_hash", sa.String(length=64), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("condition", sa.String(length=100), nullable=True),
        sa.Column("consent_version", sa.String(length=100), nullable=True),
        sa.Column("consented_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("status", sa.String(length=20), server_default=sa.text("'invited'"), nullable=False),
        _created(),
        sa.CheckConstraint(
            "status IN ('invited', 'consented', 'training', 'done')",
            name=op.f("ck_participants_status"),
        ),
        sa.ForeignKeyConstraint(
            ["study_id"], ["studies.id"], name=op.f("fk_participants_study_id_studies"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_participants_run_id_runs"), ondelete="SET NULL"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_participants")),
        sa.UniqueConstraint("study_id", "pseudonym", name=op.f("uq_participants_study_id_pseudonym")),
        sa.UniqueConstraint("token_hash", name=op.f("uq_participants_token_hash")),
    )  # fmt: skip
    op.create_index(op.f("ix_participants_study_id"), "participants", ["study_id"], unique=False)
    op.create_index(op.f("ix_participants_run_id"), "participants", ["run_id"], unique=False)
    op.create_table(
        "participant_identities",
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.Integer(), nullable=False),
        sa.Column("external_id", sa.Text(), nullable=False),
        sa.ForeignKeyConstraint(
            ["participant_id"], ["participants.id"],
            name=op.f("fk_participant_identities_participant_id_participants"), ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["study_id"], ["studies.id"],
            name=op.f("fk_participant_identities_study_id_studies"), ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("participant_id", name=op.f("pk_participant_identities")),
    )  # fmt: skip
    op.create_index(
        op.f("ix_participant_identities_study_id"),
        "participant_identities",
        ["study_id"],
        unique=False,
    )


def downgrade() -> None:
    op.drop_table("participant_identities")
    op.drop_table("participants")
    op.drop_table("studies")
