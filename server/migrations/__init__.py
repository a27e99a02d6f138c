"""The evaluation server's database migrations (Alembic)."""
