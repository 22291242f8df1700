"""Users who may acknowledge alarms, every acknowledgement kept, and what the dashboard needs of an element value.

- ``users``: who may acknowledge (name, Werkzeug password hash, when added, whether still allowed);
- ``acknowledgements``: one row per acknowledgement of an alarm (who, when, comment, the episode and level it
  acknowledged), so a second acknowledgement adds a row instead of replacing the first;
- ``element_values.nominal``, ``label``, ``reason``, ``trust_reason``: the nominal value (SI) for the % of
  nominal, the element in plain words, why the verdict is "not assessable" and why trust is "not assessed"
  (null in rows recorded before this revision: the dashboard then says what it does not know).

The acknowledgement revision 0001 kept on an alarm (``alarms.acked_by``) is copied into ``acknowledgements``.

Revision ID: 0002
Revises: 0001
Create Date: 2026-12-01
"""
from alembic import op
import sqlalchemy as sa

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "users",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("name", sa.String(100), nullable=False, unique=True),
        sa.Column("password_hash", sa.String(300), nullable=False),
        sa.Column("created_at", sa.DateTime, nullable=False),
        sa.Column("active", sa.Boolean, nullable=False, server_default=sa.true()),
    )
    op.create_table(
        "acknowledgements",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("alarm_id", sa.Integer, sa.ForeignKey("alarms.id"), nullable=False, index=True),
        sa.Column("user_name", sa.String(100), nullable=False),
        sa.Column("at", sa.DateTime, nullable=False),
        sa.Column("comment", sa.Text, nullable=False),
        sa.Column("raised_on", sa.Date, nullable=True),
        sa.Column("level", sa.String(20), nullable=False),
    )
    # the acknowledgements revision 0001 kept on the alarm itself (the latest one) become the first rows
    op.execute("INSERT INTO acknowledgements (alarm_id, user_name, at, comment, raised_on, level) "
               "SELECT id, acked_by, acked_at, COALESCE(ack_comment, ''), raised_on, level FROM alarms "
               "WHERE acked_by IS NOT NULL AND acked_at IS NOT NULL")
    with op.batch_alter_table("element_values") as batch:
        batch.add_column(sa.Column("nominal", sa.Float, nullable=True))
        batch.add_column(sa.Column("label", sa.String(300), nullable=True))
        batch.add_column(sa.Column("reason", sa.Text, nullable=True))
        batch.add_column(sa.Column("trust_reason", sa.Text, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("element_values") as batch:
        for column in ("trust_reason", "reason", "label", "nominal"):
            batch.drop_column(column)
    op.drop_table("acknowledgements")
    op.drop_table("users")
