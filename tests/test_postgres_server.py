"""The PostgreSQL test server fixture starts a real server (Debian's package) and gives empty databases."""
from pg_server import postgres_server, postgres_url  # noqa: F401 - fixtures


def test_postgres_fixture_gives_a_fresh_real_database(postgres_url, postgres_server):  # noqa: F811
    import psycopg

    assert postgres_url.startswith("postgresql+psycopg://")
    dsn = postgres_url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(dsn, autocommit=True) as conn:
        version = conn.execute("SHOW server_version").fetchone()[0]
        assert int(version.split(".")[0]) >= 12
        assert conn.execute("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'").fetchone()[0] == 0
        conn.execute("CREATE TABLE t (x double precision)")
        conn.execute("INSERT INTO t VALUES (1.5e-7)")
        assert conn.execute("SELECT x FROM t").fetchone()[0] == 1.5e-7
    other = postgres_server.create_database("impactval_other_db")
    with psycopg.connect(other.replace("postgresql+psycopg://", "postgresql://")) as conn:
        assert conn.execute("SELECT count(*) FROM pg_tables WHERE schemaname = 'public'").fetchone()[0] == 0
