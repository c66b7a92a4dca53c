"""Runs keep their world preset and sensor definition, by name.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-30 12:00:00.000000

Runs stored before have neither: they read as '' (the defaults, which were then the only
world and the only definition).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.add_column(
            sa.Column("world", sa.String(length=100), server_default=sa.text("''"), nullable=False)
        )
        batch.add_column(
            sa.Column("sensors", sa.String(length=100), server_default=sa.text("''"), nullable=False)
        )


def downgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.drop_column("sensors")
        batch.drop_column("world")
