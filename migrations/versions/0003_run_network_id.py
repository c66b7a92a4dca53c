"""Runs keep the id of the stored network they started from.

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-02 01:00:00.000000

Live edits of a network reach the runs started from it by this id, never by the name a
later network may take. Deleting the network sets it to NULL. Runs stored before get the
id of the network of their name made before them, if it still exists (the rule the
service used until now); otherwise NULL.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.add_column(sa.Column("network_id", sa.Integer(), nullable=True))
        batch.create_index(batch.f("ix_runs_network_id"), ["network_id"], unique=False)
        batch.create_foreign_key(
            batch.f("fk_runs_network_id_networks"), "networks", ["network_id"], ["id"],
            ondelete="SET NULL",
        )  # fmt: skip
    op.execute(
        "UPDATE runs SET network_id = (SELECT networks.id FROM networks "
        "WHERE networks.name = runs.network AND networks.created_at <= runs.created_at) "
        "WHERE runs.network IS NOT NULL"
    )


def downgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.drop_constraint(batch.f("fk_runs_network_id_networks"), type_="foreignkey")
        batch.drop_index(batch.f("ix_runs_network_id"))
        batch.drop_column("network_id")
