"""Photograph the served web viewer with headless Chromium (docs/view.png).

Rule: Debian's /usr/bin/chromium, driven by Playwright (which must not
download browsers of its own), headless with software WebGL (SwiftShader), a
fresh profile and Chromium's background networking, sync and component updates
off. Every request the page makes is listed; anything that is not 127.0.0.1 is
blocked and reported (rerun's web viewer may call home for usage analytics).

  python tools/view_picture.py REC.mcap &   # serves on 127.0.0.1:19090 / :19876
  python tools/view_screenshot.py docs/view.png
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from urllib.parse import quote, urlparse

from playwright.sync_api import sync_playwright

FLAGS = ["--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--web-port", type=int, default=19090)
    p.add_argument("--grpc-port", type=int, default=19876)
    p.add_argument("--wait-s", type=float, default=20.0, help="time for the wasm viewer to load and draw")
    p.add_argument("--size", default="1600x1000")
    p.add_argument("--query", default="", help="more web-viewer URL parameters, e.g. '&notebook=true'")
    args = p.parse_args(argv)
    width, height = (int(x) for x in args.size.split("x"))
    data = f"rerun+http://127.0.0.1:{args.grpc_port}/proxy"
    url = f"http://127.0.0.1:{args.web_port}/?url={quote(data, safe='')}{args.query}"
    blocked: list[str] = []
    with tempfile.TemporaryDirectory() as profile, sync_playwright() as pw:
        browser = pw.chromium.launch_persistent_context(profile, executable_path="/usr/bin/chromium", headless=True,
                                                        args=FLAGS, viewport={"width": width, "height": height})

        def route(r):
            if urlparse(r.request.url).hostname in ("127.0.0.1", "localhost"):
                return r.continue_()
            blocked.append(r.request.url)
            return r.abort()

        browser.route("**/*", route)
        page = browser.new_page()
        page.on("console", lambda m: print(f"console {m.type}: {m.text[:200]}", file=sys.stderr))
        page.goto(url)
        page.wait_for_timeout(args.wait_s * 1000)
        page.screenshot(path=args.out)
        browser.close()
    print(f"saved {args.out}; blocked requests off 127.0.0.1: {blocked or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
