"""A study's questionnaire answers: one row per participant and question.

Revision ID: 0006_questionnaire_answers
Revises: 0005
Create Date: 2026-12-09 10:00:00.000000

Each row keeps the question as it was asked beside the answer, by the participant's row
(their pseudonym), never a recruiter's id.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006_questionnaire_answers"
down_revision: str | Sequence[str] | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "questionnaire_answers",
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("question_no", sa.Integer(), nullable=False),
        sa.Column("question", sa.Text(), nullable=False),
        sa.Column("answer", sa.Text(), nullable=False),
        sa.Column("answered_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["participant_id"], ["participants.id"],
            name=op.f("fk_questionnaire_answers_participant_id_participants"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint(
            "participant_id", "question_no", name=op.f("pk_questionnaire_answers")
        ),
    )  # fmt: skip


def downgrade() -> None:
    op.drop_table("questionnaire_answers")
