"""Schema of the store, as an ordered list of migrations (written for SQLite; PostgreSQL gets the same
statements with wider column types, see :meth:`app.storage.dialect.Dialect.ddl`).

``V1`` is the schema of the first release exactly as it shipped (idempotent ``CREATE ... IF NOT
EXISTS``), so a database made by that release -- which has no ``schema_version`` table -- is
recognised as version 1 by running it again harmlessly. Every later change is a new entry in
:data:`MIGRATIONS`, never an edit of an old one: a database is upgraded by applying, in order, the
entries above its recorded version (see :mod:`app.storage.migrations`).
"""

V1 = """
CREATE TABLE IF NOT EXISTS logs (
    id TEXT PRIMARY KEY,
    sha256 TEXT NOT NULL UNIQUE,
    filename TEXT NOT NULL,
    size_bytes INTEGER NOT NULL,
    format TEXT NOT NULL,
    created_at TEXT NOT NULL,
    path TEXT NOT NULL,
    frames INTEGER NOT NULL,
    duration_s REAL NOT NULL,
    start_time TEXT,
    issues TEXT NOT NULL,
    meta TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS vehicles (
    name TEXT NOT NULL,
    version INTEGER NOT NULL,
    created_at TEXT NOT NULL,
    sha256 TEXT NOT NULL,
    driveline_path TEXT NOT NULL,
    database_path TEXT NOT NULL,
    signal_map_path TEXT NOT NULL,
    summary TEXT NOT NULL,
    PRIMARY KEY (name, version)
);
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    subject TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('queued', 'running', 'done', 'failed')),
    progress REAL NOT NULL,
    stage TEXT NOT NULL,
    attempts INTEGER NOT NULL,
    created_at TEXT NOT NULL,
    updated_at TEXT NOT NULL,
    started_at TEXT,
    finished_at TEXT,
    error_code TEXT,
    error_detail TEXT,
    owner_pid INTEGER
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status);
CREATE INDEX IF NOT EXISTS jobs_subject ON jobs (kind, subject);
CREATE TABLE IF NOT EXISTS analyses (
    id TEXT PRIMARY KEY,
    log_id TEXT NOT NULL REFERENCES logs (id),
    vehicle_name TEXT NOT NULL,
    vehicle_version INTEGER NOT NULL,
    options TEXT NOT NULL,
    created_at TEXT NOT NULL,
    job_id TEXT NOT NULL REFERENCES jobs (id),
    summary TEXT NOT NULL,
    FOREIGN KEY (vehicle_name, vehicle_version) REFERENCES vehicles (name, version)
);
CREATE INDEX IF NOT EXISTS analyses_log ON analyses (log_id);
"""

# API keys: only the SHA-256 of a key is stored; the key itself is shown once, when it is created.
V2_API_KEYS = """
CREATE TABLE api_keys (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    scope TEXT NOT NULL CHECK (scope IN ('read', 'write', 'admin')),
    sha256 TEXT NOT NULL,
    created_at TEXT NOT NULL,
    revoked_at TEXT
);
"""

# Jobs are owned through a lease their runner renews, not through a process id (app.storage.jobtable).
V3_JOB_LEASES = """
ALTER TABLE jobs ADD COLUMN lease_owner TEXT;
ALTER TABLE jobs ADD COLUMN lease_until REAL;
"""

# (version, what it changes, SQL): applied in order, each in one transaction.
MIGRATIONS: list[tuple[int, str, str]] = [
    (1, "logs, vehicles, jobs, analyses (first release)", V1),
    (2, "api_keys: hashed API keys with a scope", V2_API_KEYS),
    (3, "jobs.lease_owner, jobs.lease_until: job leases with heartbeats", V3_JOB_LEASES),
]
