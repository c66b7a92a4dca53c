"""Rewards keep the tick their trainer saw and the reaction window they credited.

Revision ID: 0007_reaction_window
Revises: 0006_questionnaire_answers
Create Date: 2026-12-05 23:30:00.000000

A trainer's reward may say which tick the person was looking at when they pressed; it
credits the reaction window before that tick (`core.brain.memory.credit_seen`). The log
keeps the seen tick, its episode and the window's first and last tick, and for a reward
on a stored episode's tick the records it credited; rewards logged before, and rewards
without a seen tick, have none (NULL).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0007_reaction_window"
down_revision: str | Sequence[str] | None = "0006_questionnaire_answers"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COLUMNS = ("tick_seen", "seen_episode", "window_first", "window_last", "records")


def upgrade() -> None:
    with op.batch_alter_table("rewards") as batch:
        batch.add_column(sa.Column("tick_seen", sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column("seen_episode", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("window_first", sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column("window_last", sa.BigInteger(), nullable=True))
        batch.add_column(sa.Column("records", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("rewards") as batch:
        for name in reversed(COLUMNS):
            batch.drop_column(name)
