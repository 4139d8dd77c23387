"""The experimenter's console and the questionnaire page: web pages of the lab server.

Belongs here: the routes (`app.console_routes`) that let an experimenter, behind
a token printed at start, register participants, run a study's protocol step by
step (services/protocol.py does the work), watch the running game and answer for
the study's data (export, delete, report); the questionnaire page a participant
answers after each game; their static files (plain HTML, CSS and JS, no build).
The pages keep no truth of their own: every state they show is the journal's
fold or the running game's events; every action goes through the StudyRunner.
"""
