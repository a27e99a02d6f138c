"""Alembic's environment: runs the migrations on the connection :func:`colonbench.server.db.migrate` gives it
(``config.attributes["connection"]``), or on the URL of the Alembic configuration's ``sqlalchemy.url``."""

from alembic import context

from colonbench.server.db import Base, engine

config = context.config
connection = config.attributes.get("connection")
if connection is None:
    with engine(config.get_main_option("sqlalchemy.url")).begin() as conn:
        context.configure(connection=conn, target_metadata=Base.metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()
else:
    context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()
