"""The lab: the web side of a live human session (`pairplay lab`).

Rule: the web server is a bus service like the others. `hub.LabHub` (one per
session) folds the session's events into what the pages show (`model.py`) and
publishes a page's inputs as events; it keeps no truth of its own. The
Starlette app is built by `app.create_app` from route groups, one module per
page (`board.py`: the participant's touch screen and the WebSocket every page
uses; `mirror.py`: the robot's stand-in), so another page (the experimenter's
console) is one more module and one more entry in `PAGES`. Pages are static
files (`static/`: plain HTML, CSS and JS, the card faces drawn as SVG by
`faces.js`), shipped as package data; nothing is built at install time.
`server.py` runs uvicorn in a thread and a whole lab session (`run_lab`).
"""
