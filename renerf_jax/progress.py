"""Progress bars (tqdm): count, rate and ETA on stderr."""
import sys

from tqdm.auto import tqdm


def progress_bar(total, initial=0, desc='', disable=False, unit='step'):
  """A tqdm bar with rate and ETA; refreshed at most once a second off a terminal."""
  return tqdm(total=total, initial=initial, desc=desc, disable=disable, unit=unit,
              dynamic_ncols=True, file=sys.stderr,
              mininterval=0.2 if sys.stderr.isatty() else 5.)
