"""`LruCache`, the one bounded cache type of the compiler's per-process caches."""

from addt_dsl.lru import LruCache


def test_least_recently_used_goes_first_and_eviction_is_reported():
    evicted = []
    c = LruCache(2, on_evict=evicted.append)
    c.put("a", 1)
    c.put("b", 2)
    assert c.get("a") == 1  # "a" is now the most recent: "b" goes next
    c.put("c", 3)
    assert evicted == [2] and "b" not in c and c.get("a") == 1 and c.get("c") == 3 and len(c) == 2
    c.put("a", 10)  # a value stored again replaces the old one without evicting anything
    assert c.get("a") == 10 and evicted == [2] and len(c) == 2
    assert c.get("missing") is None


def test_falsy_values_are_kept():
    c = LruCache(1)
    c.put("ok", ())
    assert c.get("ok") == ()
