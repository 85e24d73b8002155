"""Credentials never stored (issue 52): `mask_secrets`, the one function every recorded string passes
through, against generated URLs (user names and passwords with odd characters: "@", ":", "/",
percent-escapes) embedded at random places in generated text, and against structures of them."""

from __future__ import annotations

import json
from urllib.parse import unquote

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab.errors import MASK, mask_secrets

pytestmark = pytest.mark.fast

GEN = settings(max_examples=300, deadline=None, derandomize=True, database=None)

SCHEMES = st.sampled_from(["http", "https", "postgresql", "postgresql+psycopg2", "mysql", "ray", "mlflow-x"])
USERS = st.text("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-+@%", min_size=1, max_size=12)
# a password may hold anything but whitespace and quotes (which end a URL in free text)
PASSWORDS = st.text(st.characters(min_codepoint=33, max_codepoint=126, exclude_characters="'\"<>`"),
                    min_size=1, max_size=20) | st.builds(lambda a, b: f"{a}%40{b}%2F", st.text("abc123", max_size=4),
                                                          st.text("xyz:", max_size=4))
HOSTS = st.from_regex(r"[a-z0-9]([a-z0-9.-]{0,12}[a-z0-9])?(:[0-9]{1,5})?", fullmatch=True)
PATHS = st.from_regex(r"(/[A-Za-z0-9._~-]{0,8}){0,3}(\?[a-z]{1,5}=[a-z0-9]{0,5}(&[a-z]{1,5}=[a-z0-9]{0,5})?)?",
                      fullmatch=True).filter(lambda p: not any(w in p for w in ("pass", "pwd", "key", "token",
                                                                                "auth", "secret", "sig")))
# free text around URLs: anything (unicode too) that holds no URL of its own
TEXT = st.text(max_size=40).filter(lambda t: "://" not in t)
ENDS = st.sampled_from([" ", "\n", "'", '"', "\t"])  # what ends a URL in free text


def _parts_quote(secret: str, *others: str) -> bool:
    """The secret (or its decoded form) stands in other parts of the text: then it is masked there too,
    and the text is not the simple expected one."""
    return any(f in o for f in (secret, unquote(secret)) for o in others)


@GEN
@given(SCHEMES, USERS, PASSWORDS, HOSTS, PATHS, TEXT, ENDS, TEXT)
def test_a_password_in_a_url_anywhere_in_text_is_masked(scheme, user, password, host, path, before, end, after):
    url = f"{scheme}://{user}:{password}@{host}{path}"
    text = before + url + end + after
    shown = mask_secrets(text)
    if not _parts_quote(password, before, after, user, host, path, scheme):
        assert shown == before + f"{scheme}://{user}:{MASK}@{host}{path}" + end + after
    if len(password) >= 3 and not _parts_quote(password, MASK):
        assert password not in shown
        if len(unquote(password)) >= 3:
            assert unquote(password) not in shown


@GEN
@given(SCHEMES, HOSTS, st.sampled_from(["token", "password", "api_key", "X-Auth", "signature"]),
       st.text("abcdefghijklmnopqrstuvwxyz0123456789%-_.~", min_size=3, max_size=16), TEXT, ENDS, TEXT)
def test_a_credential_query_parameter_is_masked(scheme, host, name, secret, before, end, after):
    text = f"{before}{scheme}://{host}/db?a=1&{name}={secret}{end}{after}"
    shown = mask_secrets(text)
    if not _parts_quote(secret, before, after, host, scheme, name):
        assert shown == f"{before}{scheme}://{host}/db?a=1&{name}={MASK}{end}{after}"
        assert secret not in shown


@GEN
@given(st.lists(st.tuples(TEXT, SCHEMES, HOSTS, PATHS), max_size=4), TEXT)
def test_text_without_credentials_is_unchanged(pieces, last):
    text = "".join(f"{t} {s}://{h}{p} " for t, s, h, p in pieces) + last
    assert mask_secrets(text) == text


@GEN
@given(TEXT)
def test_free_text_without_a_url_is_unchanged(text):
    assert mask_secrets(text) == text


SECRET = "s3cr3t@pa/ss:w%2Fd"  # one fixed credential, so that its absence can be checked anywhere
LEAVES = st.one_of(st.integers(), st.floats(allow_nan=False), st.booleans(), st.none(), TEXT,
                   st.builds(lambda b, a: f"{b}mlflow=http://me:{SECRET}@host:5000 {a}", TEXT, TEXT))
KEYS = st.one_of(TEXT, st.just(f"postgresql://u:{SECRET}@db/x"))
STRUCTURES = st.recursive(LEAVES, lambda inner: st.lists(inner, max_size=3) | st.tuples(inner, inner)
                          | st.dictionaries(KEYS, inner, max_size=3), max_leaves=12)


def _shape(value):
    if isinstance(value, dict):
        return ("dict", len(value))
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [_shape(v) for v in value])
    return type(value).__name__


@GEN
@given(STRUCTURES)
def test_structures_keep_their_shape_and_lose_every_credential(value):
    shown = mask_secrets(value)
    assert SECRET not in json.dumps(shown, default=str) and unquote(SECRET) not in json.dumps(shown, default=str)
    if not isinstance(value, dict) or len({mask_secrets(k) for k in value}) == len(value):
        assert _shape(shown) == _shape(value)
    assert mask_secrets(shown) == shown  # idempotent: a recorded value compares equal to it masked again


@pytest.mark.parametrize(("text", "shown"), [
    ("train X --track mlflow=http://user:pw@host", "train X --track mlflow=http://user:***@host"),
    ("train X --track 'mlflow=https://u:p@ss@h:5000' --seed 1", "train X --track 'mlflow=https://u:***@h:5000' --seed 1"),
    ("--storage postgresql://u:pa/ss@db.example/optuna", "--storage postgresql://u:***@db.example/optuna"),
    ("http://h/x?token=abc&a=1", "http://h/x?token=***&a=1"),
    ("sqlite:////abs/study.db and file:///tmp/mlruns", "sqlite:////abs/study.db and file:///tmp/mlruns"),
    ("mail me@example.org, user:pw@host is no URL", "mail me@example.org, user:pw@host is no URL"),
    ("ray://u:p%40ss@10.0.0.5:10001 refused: bad password p@ss", "ray://u:***@10.0.0.5:10001 refused: bad password ***"),
])
def test_listed_forms(text, shown):
    assert mask_secrets(text) == shown


def test_other_values_are_returned_as_they_are():
    marker = object()
    assert mask_secrets(marker) is marker and mask_secrets(3.5) == 3.5 and mask_secrets(None) is None


def test_the_html_report_shows_no_credential_of_the_files_it_reads(tmp_path):
    """A run folder written before masking (or by hand) quotes a password in config.toml and summary.json:
    the report shows every value masked (jinja's finalize: each value on the page passes mask_secrets)."""
    from motorlab.report.html import build_report

    run = tmp_path / "run"
    run.mkdir()
    secret = "s3cr3t@pa/ss"
    (run / "config.toml").write_text(f'track = "mlflow=http://me:{secret}@host:5000"\nseed = 0\n')
    (run / "summary.json").write_text(json.dumps({"target": f"train X --storage postgresql://me:{secret}@db/x",
                                                  "return_mean": 1.5}))
    html = build_report([run], tmp_path / "report.html").read_text()
    assert secret not in html and "s3cr3t" not in html
    assert "postgresql://me:***@db/x" in html and "http://me:***@host:5000" in html
