"""A report page printed to PDF by headless Chromium, when Chromium is installed.

Chromium lays the page out with the report's own ``@media print`` rules (A4, page breaks),
so the PDF is what a person gets from the browser's Print dialog, with no second layout
engine to keep in step with the CSS. Found as ``$TCR_CHROMIUM`` or ``chromium``,
``chromium-browser``, ``google-chrome`` on the PATH (Debian: ``apt-get install chromium``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

#: Executables tried in this order when $TCR_CHROMIUM is not set.
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")

#: Flags for a machine with no display, no GPU and no outside network; the page loads only
#: files beside it. The virtual time budget lets the page finish laying out before printing.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars", "--no-pdf-header-footer", "--virtual-time-budget=4000")

#: Longest a print may take [s] before it is given up (the report is then written without PDF).
PRINT_TIMEOUT_S = 120


def find_chromium() -> str | None:
    """The Chromium executable to print with, or None when there is none."""
    given = os.environ.get("TCR_CHROMIUM")
    if given:
        return given if os.path.isfile(given) and os.access(given, os.X_OK) else None
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def print_to_pdf(page: Path) -> tuple[bytes | None, str]:
    """Print the HTML file ``page`` (its images beside it) to PDF.

    Returns
    -------
    pdf : bytes or None
        The PDF, or None when it could not be made.
    why : str
        Empty, or why there is no PDF (one line).
    """
    chromium = find_chromium()
    if chromium is None:
        return None, ("no Chromium found (install it, e.g. 'apt-get install chromium', or set TCR_CHROMIUM "
                      "to its executable)")
    with tempfile.TemporaryDirectory(prefix="tcr-pdf-") as tmp:
        target = Path(tmp) / "report.pdf"
        command = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={Path(tmp) / 'profile'}",
                   f"--print-to-pdf={target}", Path(page).resolve().as_uri()]
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=PRINT_TIMEOUT_S,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return None, f"Chromium did not finish printing within {PRINT_TIMEOUT_S} s"
        except OSError as exc:
            return None, f"Chromium ({chromium}) did not start: {exc.strerror}"
        if done.returncode != 0 or not target.is_file():
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            return None, f"Chromium failed to print (exit {done.returncode}: {last[:200]})"
        data = target.read_bytes()
    if not data.startswith(b"%PDF"):
        return None, "Chromium wrote no PDF"
    return data, ""
