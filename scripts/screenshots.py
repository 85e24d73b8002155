"""Screenshots of HTML reports, as a reader first sees them, taken by headless Chromium.

    python scripts/screenshots.py REPORT.html=OUT.png ...   [--height PIXELS]

`make screenshots` runs the three demo studies (finished steps are kept) and writes
docs/screenshots/*.png with this script; the README shows them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"  # Debian's, installed by scripts/setup.sh --browser


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("pairs", nargs="+", metavar="REPORT=PNG", help="a report and the screenshot to write")
    parser.add_argument("--height", type=int, default=1500, help="pixels from the top of the page (default 1500)")
    parser.add_argument("--width", type=int, default=1280, help="viewport width in pixels (default 1280)")
    args = parser.parse_args()
    jobs = []
    for pair in args.pairs:
        report, sep, png = pair.partition("=")
        if not sep or not Path(report).is_file():
            print(f"screenshots: {pair!r}: give REPORT.html=OUT.png with an existing report "
                  "(make demo writes them under runs/)", file=sys.stderr)
            return 2
        jobs.append((Path(report), Path(png)))

    from PIL import Image
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": args.width, "height": args.height}, device_scale_factor=1)
        for report, png in jobs:
            page.goto(report.resolve().as_uri())
            page.wait_for_load_state("load")
            png.parent.mkdir(parents=True, exist_ok=True)
            tmp = png.with_suffix(".tmp.png")
            page.screenshot(path=str(tmp), full_page=False)
            with Image.open(tmp) as shot:  # 256 colours: a third of the bytes in the repository, text as sharp
                shot.convert("RGB").quantize(256, dither=Image.Dither.NONE).save(tmp, optimize=True)
            tmp.replace(png)  # a screenshot is whole or absent
            print(f"{report} -> {png}")
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
