"""Alembic environment of the monitoring database: runs on the connection suspid hands it."""

from alembic import context

from suspid.fleet.schema import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
