"""Rewards keep the id they got on arrival.

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-05 18:30:00.000000

A reward is named by `uid` from its arrival on: the trainer's answer, the log, its event
on the stream and the console. Rewards logged before have none ("").
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | Sequence[str] | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("rewards") as batch:
        batch.add_column(
            sa.Column("uid", sa.String(length=64), server_default=sa.text("''"), nullable=False)
        )


def downgrade() -> None:
    with op.batch_alter_table("rewards") as batch:
        batch.drop_column("uid")
