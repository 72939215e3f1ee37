"""What a KRL / RAPID program may be called: the one rule every program name passes
(:func:`program_name_problem`), from the ``program_name`` option (Python API, the service's
``/export``) and from the output file's stem (``grasplan export --format krl|rapid -o NAME.src``),
and a suggestion for a refused name (:func:`suggest_program_name`).

This module imports nothing from grasplan but its errors: the export registry (below the result
module) and the service's body checks call it.
"""
from __future__ import annotations

import re

#: KRL names have at most 24 characters; RAPID identifiers at most 32, and the module declares
#: ``<name>_main``, ``<name>_tool`` and ``<name>_wobj`` (24 + 5 <= 32)
MAX_LENGTH = 24
#: the form of a program name
PROGRAM_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,%d}" % (MAX_LENGTH - 1))

#: KRL keywords (KUKA System Software 8.x), upper-cased. Source: KUKA "Quickguide KRL-Syntax, KSS
#: Release 8.x" (2012): names have at most 24 characters, letters, digits, ``_`` and ``$``, do not
#: begin with a digit and are not a keyword. Keywords: the KRL reference's keyword list (as in the
#: grammars-v4 ``krl.g4`` lexer) plus the KSS 8 spline, trigger and interrupt keywords (as
#: highlighted by krl-for-vim ``syntax/krl.vim``)
KRL_RESERVED = frozenset("""
AND ANIN ANOUT ASYCANCEL ASYCONT ASYPTP ASYSTOP B_AND B_EXOR B_NOT B_OR BOOL BRAKE BRAKE_F C_DIS
C_ORI C_PTP C_SPL C_VEL CASE CAST_FROM CAST_TO CHANNEL CHAR CIRC CIRC_REL CONFIRM CONST CONST_VEL
CONTINUE DECL DEF DEFAULT DEFDAT DEFFCT DELAY DIGIN DISABLE DISTANCE DIV DO ELSE ENABLE END ENDDAT
ENDFCT ENDFOR ENDIF ENDLOOP ENDSPLINE ENDSWITCH ENDWHILE ENUM EXIT EXOR EXT EXTFCT EXTFCTP EXTP
FALSE FOR GLOBAL GOTO HALT IF IMPORT INT INTERRUPT IS LIN LIN_REL LOOP MAXIMUM MINIMUM MOD NOT OFF
ON ON_ERROR_PROCEED ONSTART OR PATH PRIO PTP PTP_REL PUBLIC REAL REPEAT RESUME RETURN SCIRC
SCIRC_REL SEC SIGNAL SLIN SLIN_REL SPL SPLINE SPTP SPTP_REL STEP STOP STRUC SWITCH THEN TIME_BLOCK
TO TRIGGER TRUE UNTIL WAIT WHEN WHILE WITH
""".split())

#: RAPID reserved words (ABB RobotWare 6/7), upper-cased. Source: ABB "Technical reference manual -
#: RAPID kernel" (3HAC050946-001), "Reserved words" (identifiers at most 32 characters); the same
#: list as the token set of the intellij-rapid grammar (``Rapid.bnf``)
RAPID_RESERVED = frozenset("""
ALIAS AND BACKWARD CASE CONNECT CONST DEFAULT DIV DO ELSE ELSEIF ENDFOR ENDFUNC ENDIF ENDMODULE
ENDPROC ENDRECORD ENDTEST ENDTRAP ENDWHILE ERROR EXIT FALSE FOR FROM FUNC GOTO IF INOUT LOCAL MOD
MODULE NOSTEPIN NOT NOVIEW OR PERS PROC RAISE READONLY RECORD RETRY RETURN STEP SYSMODULE TASK
TEST THEN TO TRAP TRUE TRYNEXT UNDO VAR VIEWONLY WHILE WITH XOR
""".split())

#: names the exported KRL program declares or calls (grasplan.export.krl): a program of the same
#: name would clash with them (``BAS`` is KUKA's own motion-setup program it calls; ``IN`` and
#: ``OUT`` qualify a subroutine's parameters)
KRL_PROGRAM_NAMES = frozenset("""
BAS INITMOV GRASPLAN_GRIPPER OPENING_MM TOOL_GL BASE_GL XGRASP XRETREAT XLIFT XPLACE I FRAME E6POS
E6AXIS IN OUT
""".split())
#: names the exported RAPID module declares or calls (grasplan.export.rapid)
RAPID_PROGRAM_NAMES = frozenset("""
GRASPLAN_GRIPPER_OPEN GRASPLAN_GRIPPER_CLOSE OPENING_MM WIDTH_MM RT_GRASP RT_RETREAT RT_LIFT RT_PLACE
TOOLDATA WOBJDATA JOINTTARGET ROBTARGET NUM MOVEABSJ MOVEL CONFL WAITTIME FINE V50 V200 NOEOFFS WOBJ
""".split())
#: numbered names the programs declare: KRL ``XP1, XP2, ...`` (joint targets), RAPID ``jt_1, ...``
_NUMBERED = (("KRL", re.compile(r"XP\d+")), ("RAPID", re.compile(r"JT_\d+")))

#: what each language is, in messages
_KRL = "KRL (KUKA System Software 8.x)"
_RAPID = "RAPID (ABB RobotWare 6/7)"


def program_name_problem(name: object) -> str | None:
    """Why ``name`` cannot name a KRL/RAPID program (``None`` when it can), one clause for a
    message: what is wrong, in the user's spelling.

    A program name is a letter, then letters, digits or ``_``, at most :data:`MAX_LENGTH` characters;
    it is not a reserved word of KRL or of RAPID, and not a name the exported program itself declares
    or calls (its targets, tool and base data, gripper routine, the KUKA ``BAS`` program). Both
    languages ignore case, so neither does the rule. One rule for both languages: the option is
    shared by the two formats (``grasplan.results.export_registry.ExportOptions``), and a name one
    controller refuses is a poor name for the other."""
    if not isinstance(name, str):
        return f"expected a string, got {type(name).__name__}"
    if not PROGRAM_NAME.fullmatch(name):
        shown = name if len(name) <= 40 else name[:37] + "..."
        return (f"{shown!r} is not a program name: use a letter, then letters, digits or _ "
                f"(at most {MAX_LENGTH} characters)")
    up = name.upper()
    langs = [lang for lang, words in ((_KRL, KRL_RESERVED), (_RAPID, RAPID_RESERVED)) if up in words]
    if langs:
        return f"{name!r} is a reserved word of {' and '.join(langs)}"
    for lang, words in (("KRL", KRL_PROGRAM_NAMES), ("RAPID", RAPID_PROGRAM_NAMES)):
        if up in words:
            return f"{name!r} is a name the exported {lang} program itself declares or calls"
    for lang, pattern in _NUMBERED:
        if pattern.fullmatch(up):
            return f"{name!r} is a name the exported {lang} program itself declares (a joint target)"
    return None


def suggest_program_name(name: object) -> str:
    """A program name that passes :func:`program_name_problem`, close to ``name``: its allowed
    characters (others -> ``_``, no leading digit or ``_``, at most :data:`MAX_LENGTH`), else that
    with ``_1`` appended (``END`` -> ``END_1``; shortened to fit), else ``grasplan_pick``."""
    text = re.sub(r"[^A-Za-z0-9_]", "_", name if isinstance(name, str) else "")
    text = text.lstrip("0123456789_")
    tries = [text[:MAX_LENGTH], text + "_1", text[: MAX_LENGTH - 2] + "_1", "pick_" + text[: MAX_LENGTH - 7] + "_1"]
    return next((t for t in tries if text and program_name_problem(t) is None), "grasplan_pick")
