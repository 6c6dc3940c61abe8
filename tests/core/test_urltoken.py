"""The URL token check shared by the live view and the editor."""

import pytest

from avblocks.core.errors import AvError, ParameterError
from avblocks.core.urltoken import make_token, under_token


@pytest.mark.parametrize("path, rest", [
    ("/abc", ""), ("/abc/", "/"), ("/abc/api/run", "/api/run"),
    ("/abcd", None), ("/ab", None), ("/", None), ("", None), ("/xyz/abc/", None),
    ("/ABC/", None),
])
def test_under_token_gives_the_rest_of_the_path_or_none(path, rest):
    assert under_token(path, "abc") == rest
    b = under_token(path.encode(), "abc")
    assert b == (None if rest is None else rest.encode())


def test_make_token_is_random_url_safe_and_refuses_others_with_the_callers_error():
    a, b = make_token(), make_token()
    assert a != b and len(a) == 32 and a.replace("-", "").replace("_", "").isalnum()
    assert make_token("my-Token_1") == "my-Token_1"
    with pytest.raises(ParameterError, match="URL-safe"):
        make_token("a/b", ParameterError)
    with pytest.raises(AvError, match="URL-safe"):
        make_token("a b")
