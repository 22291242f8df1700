"""The monitoring database's first schema: runs, element values, indicators, alarms, audit.

Revision ID: 0001
Revises:
Create Date: 2026-11-27
"""
from alembic import op
import sqlalchemy as sa

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("fleet", sa.String(100), nullable=False, index=True),
        sa.Column("trainset", sa.String(100), nullable=False, index=True),
        sa.Column("vehicle", sa.String(100), nullable=False),
        sa.Column("date", sa.Date, nullable=False, index=True),
        sa.Column("mileage_km", sa.Float, nullable=True),
        sa.Column("kind", sa.String(20), nullable=False),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("config_hash", sa.String(64), nullable=False),
        sa.Column("run_dir", sa.String(1000), nullable=False),
        sa.Column("report_path", sa.String(1000), nullable=True),
        sa.Column("figure1_path", sa.String(1000), nullable=True),
        sa.Column("figure2_path", sa.String(1000), nullable=True),
        sa.Column("recorded_at", sa.DateTime, nullable=False),
        sa.UniqueConstraint("run_dir", "config_hash", name="uq_runs_dir_hash"),
    )
    op.create_table(
        "element_values",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id", ondelete="CASCADE"), nullable=False, index=True),
        sa.Column("element_group", sa.String(200), nullable=False, index=True),
        sa.Column("kind", sa.String(100), nullable=False),
        sa.Column("unit", sa.String(40), nullable=False),
        sa.Column("value", sa.Float, nullable=False),
        sa.Column("interval_low", sa.Float, nullable=False),
        sa.Column("interval_high", sa.Float, nullable=False),
        sa.Column("acceptable_low", sa.Float, nullable=True),
        sa.Column("acceptable_high", sa.Float, nullable=True),
        sa.Column("identifiable", sa.Boolean, nullable=False),
        sa.Column("trust", sa.String(20), nullable=False),
        sa.Column("verdict", sa.String(20), nullable=False),
        sa.Column("w_ref", sa.Float, nullable=True),
    )
    op.create_table(
        "indicators",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id", ondelete="CASCADE"), nullable=False, index=True),
        sa.Column("name", sa.String(60), nullable=False),
        sa.Column("segment", sa.String(200), nullable=True),
        sa.Column("channel", sa.String(200), nullable=False),
        sa.Column("value", sa.Float, nullable=False),
        sa.Column("limit", sa.Float, nullable=True),
        sa.Column("unit", sa.String(40), nullable=False),
        sa.Column("verdict", sa.String(20), nullable=False),
        sa.Column("detail", sa.Text, nullable=False),
    )
    op.create_table(
        "alarms",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("fleet", sa.String(100), nullable=False),
        sa.Column("trainset", sa.String(100), nullable=False, index=True),
        sa.Column("vehicle", sa.String(100), nullable=False),
        sa.Column("source", sa.String(200), nullable=False),
        sa.Column("state", sa.String(20), nullable=False),
        sa.Column("level", sa.String(20), nullable=False),
        sa.Column("raised_on", sa.Date, nullable=True),
        sa.Column("raised_run_id", sa.Integer, nullable=True),
        sa.Column("cleared_on", sa.Date, nullable=True),
        sa.Column("last_date", sa.Date, nullable=True),
        sa.Column("acked_by", sa.String(100), nullable=True),
        sa.Column("acked_at", sa.DateTime, nullable=True),
        sa.Column("ack_comment", sa.Text, nullable=True),
        sa.UniqueConstraint("fleet", "trainset", "vehicle", "source", name="uq_alarms_key"),
    )
    op.create_table(
        "audit",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("at", sa.DateTime, nullable=False),
        sa.Column("actor", sa.String(100), nullable=False),
        sa.Column("action", sa.String(40), nullable=False),
        sa.Column("alarm_id", sa.Integer, sa.ForeignKey("alarms.id"), nullable=True),
        sa.Column("detail", sa.Text, nullable=False),
    )


def downgrade() -> None:
    for table in ("audit", "alarms", "indicators", "element_values", "runs"):
        op.drop_table(table)
