"""paper._mappings: JAX's compiled programs released before the process runs out of memory
mappings (vm.max_map_count)."""

import jax
import jax.numpy as jnp
import pytest

from paper import _mappings


@pytest.mark.skipif(_mappings.mapping_count() is None, reason="no /proc/self/maps here")
def test_release_frees_the_mappings_of_compiled_programs(monkeypatch):
    jax.clear_caches()
    before = _mappings.mapping_count()
    for k in range(40):
        jax.jit(lambda x, k=k: jnp.sin(x) * k + jnp.cumsum(x) @ x)(jnp.ones(7 + k)).block_until_ready()
    compiled = _mappings.mapping_count()
    added = compiled - before
    assert added > 150  # XLA's CPU backend: several mappings a program (40 programs)
    # under the share of the limit: nothing released
    assert not _mappings.release_compiled_programs(share=1.0)
    assert _mappings.mapping_count() >= compiled - 10
    # past it (a limit the process already exceeds): the caches emptied, the mappings freed
    monkeypatch.setattr(_mappings, "mapping_limit", lambda: compiled // 2)
    assert _mappings.release_compiled_programs()
    # (the kernels' memory is pooled: measured 46-83% of what they took given back)
    assert _mappings.mapping_count() < compiled - added // 4


def test_the_limit_is_read_where_proc_says_it():
    limit = _mappings.mapping_limit()
    assert limit is None or limit > 0
