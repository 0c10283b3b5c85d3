"""The notebooks run top to bottom on the smallest config, so they never rot."""
import os

import nbformat
import pytest
from nbclient import NotebookClient

from conftest import REPO


@pytest.mark.parametrize('name', ['quickstart.ipynb', 'bring_your_own_llff.ipynb',
                                  'bring_your_own_capture.ipynb'])
def test_notebook_executes(name, fern_dir):
  path = REPO / 'notebooks' / name
  nb = nbformat.read(path, as_version=4)
  os.environ['RENERF_NOTEBOOK_SMALL'] = '1'
  os.environ['RENERF_DATA_DIR'] = fern_dir
  client = NotebookClient(nb, timeout=600, kernel_name='python3',
                          resources={'metadata': {'path': str(REPO / 'notebooks')}})
  client.execute()
  outputs = [o for c in nb.cells if c.cell_type == 'code' for o in c.get('outputs', [])]
  assert not [o for o in outputs if o.get('output_type') == 'error']
  text = ''.join(o.get('text', '') for o in outputs if o.get('output_type') == 'stream')
  assert '| baseline |' in text
  if name == 'bring_your_own_capture.ipynb':  # A COLMAP capture through B and R1.
    assert "(71, 80, 45, 3) train" in text and '| Re-Nerfing R1 |' in text
    assert 'validation PSNR, B then R1:' in text
  if name == 'quickstart.ipynb':  # The demo's verdict: R1 against its seed-matched control.
    assert "| control (D's seed, no pseudo-views) |" in text and 'R1 - control: PSNR' in text
