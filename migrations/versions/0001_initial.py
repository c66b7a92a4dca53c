"""The initial schema: catalogue, networks and their history, runs and what they learn.

Revision ID: 0001
Revises:
Create Date: 2026-11-22 00:16:43.210852
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op


revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "logical_sensors",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("physical", sa.JSON(), nullable=False),
        sa.Column("processing", sa.String(length=40), nullable=False),
        sa.Column("objective", sa.String(length=100), nullable=False),
        sa.Column("level", sa.String(length=10), nullable=False),
        sa.Column("priority", sa.Integer(), nullable=False),
        sa.Column("weight", sa.Double(), nullable=False),
        sa.CheckConstraint("level IN ('low', 'high')", name=op.f("ck_logical_sensors_level")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_logical_sensors")),
        sa.UniqueConstraint("name", name=op.f("uq_logical_sensors_name")),
    )
    op.create_table(
        "networks",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("description", sa.Text(), nullable=False),
        sa.Column("builtin", sa.Boolean(), server_default=sa.false(), nullable=False),
        sa.Column("version", sa.Integer(), server_default=sa.text("1"), nullable=False),
        sa.Column(
            "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.Column(
            "updated_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_networks")),
        sa.UniqueConstraint("name", name=op.f("uq_networks_name")),
    )
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("condition", sa.String(length=100), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("episodes", sa.Integer(), nullable=True),
        sa.Column("mode", sa.String(length=20), nullable=False),
        sa.Column("hz", sa.Double(), nullable=False),
        sa.Column("network", sa.String(length=100), nullable=True),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("status", sa.String(length=20), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column(
            "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("episodes_done", sa.Integer(), server_default=sa.text("0"), nullable=False),
        sa.Column("successes", sa.Integer(), server_default=sa.text("0"), nullable=False),
        sa.Column("ticks", sa.BigInteger(), server_default=sa.text("0"), nullable=False),
        sa.Column("checkpoint_episode", sa.Integer(), nullable=True),
        sa.Column("checkpoint_tick", sa.BigInteger(), nullable=True),
        sa.Column("checkpoint", sa.LargeBinary(), nullable=True),
        sa.CheckConstraint("mode IN ('fast', 'realtime')", name=op.f("ck_runs_mode")),
        sa.CheckConstraint(
            "status IN ('created', 'running', 'paused', 'finished', 'stopped', 'interrupted', 'failed')",
            name=op.f("ck_runs_status"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_runs")),
        sqlite_autoincrement=True,
    )
    op.create_index(op.f("ix_runs_status"), "runs", ["status"], unique=False)

    op.create_table(
        "behaviours",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("family", sa.String(length=40), nullable=False),
        sa.Column("speed_mps", sa.Double(), nullable=False),
        sa.Column("turn_dps", sa.Double(), nullable=False),
        sa.Column("ticks", sa.Integer(), nullable=False),
        sa.Column("mode", sa.String(length=20), nullable=False),
        sa.Column("synthesized", sa.Boolean(), server_default=sa.false(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.CheckConstraint(
            "mode IN ('align', 'steer', 'constant')", name=op.f("ck_behaviours_mode")
        ),
        sa.CheckConstraint("ticks >= 1", name=op.f("ck_behaviours_ticks")),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_behaviours_run_id_runs"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_behaviours")),
        sa.UniqueConstraint("run_id", "name", name=op.f("uq_behaviours_run_id_name")),
    )
    op.create_index(op.f("ix_behaviours_run_id"), "behaviours", ["run_id"], unique=False)
    op.create_index(
        "uq_behaviours_designed_name",
        "behaviours",
        ["name"],
        unique=True,
        sqlite_where=sa.text("run_id IS NULL"),
        postgresql_where=sa.text("run_id IS NULL"),
    )

    op.create_table(
        "episodes",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("episode", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("outcome", sa.String(length=40), nullable=False),
        sa.Column("cause", sa.String(length=100), nullable=True),
        sa.Column("ticks", sa.Integer(), nullable=False),
        sa.Column("start_tick", sa.BigInteger(), nullable=False),
        sa.Column("rewards", sa.Integer(), nullable=False),
        sa.Column("trace", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_episodes_run_id_runs"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("run_id", "episode", name=op.f("pk_episodes")),
    )
    op.create_table(
        "network_versions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("network_id", sa.Integer(), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("snapshot", sa.JSON(), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column(
            "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.ForeignKeyConstraint(
            ["network_id"],
            ["networks.id"],
            name=op.f("fk_network_versions_network_id_networks"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_network_versions")),
        sa.UniqueConstraint(
            "network_id", "version", name=op.f("uq_network_versions_network_id_version")
        ),
    )
    op.create_index(
        op.f("ix_network_versions_network_id"), "network_versions", ["network_id"], unique=False
    )

    op.create_table(
        "rewards",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("tick", sa.BigInteger(), nullable=False),
        sa.Column("episode", sa.Integer(), nullable=False),
        sa.Column("value", sa.Double(), nullable=False),
        sa.Column("source", sa.String(length=40), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("applied", sa.Boolean(), server_default=sa.false(), nullable=False),
        sa.Column("credited", sa.Integer(), server_default=sa.text("0"), nullable=False),
        sa.Column(
            "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_rewards_run_id_runs"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_rewards")),
        sqlite_autoincrement=True,
    )
    op.create_index(op.f("ix_rewards_run_id"), "rewards", ["run_id"], unique=False)

    op.create_table(
        "run_commands",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("tick", sa.BigInteger(), nullable=False),
        sa.Column("kind", sa.String(length=40), nullable=False),
        sa.Column("payload", sa.JSON(), nullable=False),
        sa.Column(
            "created_at", sa.DateTime(timezone=True), server_default=sa.func.now(), nullable=False
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_run_commands_run_id_runs"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_run_commands")),
        sqlite_autoincrement=True,
    )
    op.create_index(op.f("ix_run_commands_run_id"), "run_commands", ["run_id"], unique=False)

    op.create_table(
        "stimuli",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("sensor_id", sa.Integer(), nullable=False),
        sa.Column("objective", sa.String(length=100), nullable=False),
        sa.Column("level", sa.String(length=10), nullable=False),
        sa.Column("priority", sa.Integer(), nullable=False),
        sa.Column("rule", sa.JSON(), nullable=False),
        sa.CheckConstraint("level IN ('low', 'high')", name=op.f("ck_stimuli_level")),
        sa.ForeignKeyConstraint(
            ["sensor_id"], ["logical_sensors.id"], name=op.f("fk_stimuli_sensor_id_logical_sensors")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_stimuli")),
        sa.UniqueConstraint("name", name=op.f("uq_stimuli_name")),
    )
    op.create_index(op.f("ix_stimuli_sensor_id"), "stimuli", ["sensor_id"], unique=False)

    op.create_table(
        "associations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("network_id", sa.Integer(), nullable=False),
        sa.Column("stimulus_id", sa.Integer(), nullable=False),
        sa.Column("behaviour_id", sa.Integer(), nullable=False),
        sa.Column("strength", sa.Double(), nullable=False),
        sa.Column("source", sa.String(length=20), nullable=False),
        sa.Column("locked", sa.Boolean(), server_default=sa.false(), nullable=False),
        sa.CheckConstraint(
            "source IN ('innate', 'dp', 'learned', 'kp', 'expert', 'designed')",
            name=op.f("ck_associations_source"),
        ),
        sa.ForeignKeyConstraint(
            ["behaviour_id"],
            ["behaviours.id"],
            name=op.f("fk_associations_behaviour_id_behaviours"),
        ),
        sa.ForeignKeyConstraint(
            ["network_id"],
            ["networks.id"],
            name=op.f("fk_associations_network_id_networks"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["stimulus_id"], ["stimuli.id"], name=op.f("fk_associations_stimulus_id_stimuli")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_associations")),
        sa.UniqueConstraint(
            "network_id",
            "stimulus_id",
            "behaviour_id",
            name=op.f("uq_associations_network_id_stimulus_id_behaviour_id"),
        ),
    )
    op.create_index(
        op.f("ix_associations_network_id"), "associations", ["network_id"], unique=False
    )

    op.create_table(
        "ltm",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("stimulus_id", sa.Integer(), nullable=False),
        sa.Column("behaviour_id", sa.Integer(), nullable=False),
        sa.Column("reliability", sa.Double(), nullable=False),
        sa.ForeignKeyConstraint(
            ["behaviour_id"], ["behaviours.id"], name=op.f("fk_ltm_behaviour_id_behaviours")
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_ltm_run_id_runs"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["stimulus_id"], ["stimuli.id"], name=op.f("fk_ltm_stimulus_id_stimuli")
        ),
        sa.PrimaryKeyConstraint("run_id", "stimulus_id", "behaviour_id", name=op.f("pk_ltm")),
    )
    op.create_table(
        "rltm",
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("stimulus_id", sa.Integer(), nullable=False),
        sa.Column("behaviour_id", sa.Integer(), nullable=False),
        sa.Column("reliability", sa.Double(), nullable=False),
        sa.ForeignKeyConstraint(
            ["behaviour_id"], ["behaviours.id"], name=op.f("fk_rltm_behaviour_id_behaviours")
        ),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_rltm_run_id_runs"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["stimulus_id"], ["stimuli.id"], name=op.f("fk_rltm_stimulus_id_stimuli")
        ),
        sa.PrimaryKeyConstraint("run_id", "stimulus_id", "behaviour_id", name=op.f("pk_rltm")),
    )
    op.create_table(
        "run_associations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("stimulus_id", sa.Integer(), nullable=False),
        sa.Column("behaviour_id", sa.Integer(), nullable=False),
        sa.Column("strength", sa.Double(), nullable=False),
        sa.Column("source", sa.String(length=20), nullable=False),
        sa.Column("locked", sa.Boolean(), server_default=sa.false(), nullable=False),
        sa.CheckConstraint(
            "source IN ('innate', 'dp', 'learned', 'kp', 'expert', 'designed')",
            name=op.f("ck_run_associations_source"),
        ),
        sa.ForeignKeyConstraint(
            ["behaviour_id"],
            ["behaviours.id"],
            name=op.f("fk_run_associations_behaviour_id_behaviours"),
        ),
        sa.ForeignKeyConstraint(
            ["run_id"],
            ["runs.id"],
            name=op.f("fk_run_associations_run_id_runs"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["stimulus_id"], ["stimuli.id"], name=op.f("fk_run_associations_stimulus_id_stimuli")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_run_associations")),
        sa.UniqueConstraint(
            "run_id",
            "stimulus_id",
            "behaviour_id",
            name=op.f("uq_run_associations_run_id_stimulus_id_behaviour_id"),
        ),
    )
    op.create_index(
        op.f("ix_run_associations_run_id"), "run_associations", ["run_id"], unique=False
    )


def downgrade() -> None:
    op.drop_table("run_associations")
    op.drop_table("rltm")
    op.drop_table("ltm")
    op.drop_table("associations")
    op.drop_table("stimuli")
    op.drop_table("run_commands")
    op.drop_table("rewards")
    op.drop_table("network_versions")
    op.drop_table("episodes")
    op.drop_table("behaviours")
    op.drop_table("runs")
    op.drop_table("networks")
    op.drop_table("logical_sensors")
