"""The package's shape (issue 50): no import circle, each backbone behind its own entry
module, no file over 400 lines, and docs/architecture.md's module map true to the code."""
import importlib.util
import os

from conftest import REPO

_spec = importlib.util.spec_from_file_location('make_architecture',
                                               REPO / 'docs' / 'make_architecture.py')
arch = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(arch)

MAX_LINES = 400
# Each backbone's package, and the one module of it that code outside may import.
BACKBONES = {'renerf_jax.nerf': 'renerf_jax.nerf.backbone',
             'renerf_jax.gaussians': 'renerf_jax.gaussians.backbone'}


def test_the_circle_finder_finds_circles():
  edges = {('a', 'b'), ('b', 'c'), ('c', 'a'), ('c', 'd'), ('d', 'e'), ('e', 'd')}
  assert arch.circles('abcdef', edges) == [['a', 'b', 'c'], ['d', 'e']]
  assert arch.circles('abc', {('a', 'b'), ('b', 'c')}) == []


def test_the_import_graph_reads_every_import_form(tmp_path):
  pkg = tmp_path / 'pkg'
  (pkg / 'sub').mkdir(parents=True)
  (pkg / '__init__.py').write_text('')
  (pkg / 'a.py').write_text('from pkg import b\nimport pkg.sub.c\n')
  (pkg / 'b.py').write_text('def f():\n  from pkg.sub import c  # inside a function\n')
  (pkg / 'sub' / '__init__.py').write_text('from . import c\n')
  (pkg / 'sub' / 'c.py').write_text('from ..a import x\nfrom pkg.sub import nothing\n')
  mods = arch.modules(str(pkg))
  assert set(mods) == {'pkg', 'pkg.a', 'pkg.b', 'pkg.sub', 'pkg.sub.c'}
  assert arch.imports(mods) == {('pkg.a', 'pkg.b'), ('pkg.a', 'pkg.sub.c'),
                                ('pkg.b', 'pkg.sub.c'), ('pkg.sub', 'pkg.sub.c'),
                                ('pkg.sub.c', 'pkg.a'), ('pkg.sub.c', 'pkg.sub')}
  assert arch.circles(mods, arch.imports(mods)) == [['pkg.a', 'pkg.b', 'pkg.sub', 'pkg.sub.c']]


def test_no_import_circle_in_the_package():
  mods = arch.modules()
  assert arch.circles(mods, arch.imports(mods)) == []


def test_backbones_are_reached_through_their_entry_module_only():
  mods = arch.modules()
  bad = []
  for importer, imported in sorted(arch.imports(mods)):
    for package, entry in BACKBONES.items():
      inside = importer == package or importer.startswith(package + '.')
      if (imported.startswith(package + '.') and not inside and imported != entry
          and not importer.startswith('renerf_jax.uncertainty.')):
        bad.append(f'{importer} -> {imported}')
  assert not bad, bad


def test_no_file_of_the_package_is_over_400_lines():
  long = {os.path.relpath(p, REPO): n for p in arch.modules().values()
          if (n := sum(1 for _ in open(p, encoding='utf-8'))) > MAX_LINES}
  assert not long, long


def test_the_module_map_is_generated_from_the_code():
  text = (REPO / 'docs' / 'architecture.md').read_text(encoding='utf-8')
  assert arch.page_with(text, arch.generated()) == text, (
      'docs/architecture.md is stale: run python docs/make_architecture.py')
