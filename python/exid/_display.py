"""How a StudyResult shows itself in Jupyter: a table of its key figures, its parameters and the
validation figure (measured and predicted values of each equation) as an embedded PNG."""

from __future__ import annotations

import base64
import html
import io
import math
from typing import TYPE_CHECKING, Any, List, Optional, Tuple

if TYPE_CHECKING:  # pragma: no cover
    from ._study import StudyResult

# Parameters shown in the table (all of them are in res.parameters and res.tables).
_MAX_PARAMETERS = 12


def _number(x: Any) -> str:
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, (int, float)):
        return f"{x:.6g}" if math.isfinite(x) else str(x)
    return str(x)


def key_figures(res: "StudyResult") -> List[Tuple[str, str]]:
    """(quantity, value) rows: what the report's first table says."""
    s = res.summary
    rows: List[Tuple[str, str]] = [("status", res.status)]
    if res.message:
        rows.append(("message", res.message))
    robot = s.get("robot") or {}
    if isinstance(robot, dict) and robot.get("name"):
        rows.append(("robot", f"{robot['name']} ({robot.get('dof', '?')} dof)"))
    exp = s.get("experiment") or {}
    if isinstance(exp, dict) and exp.get("samples") is not None:
        rows.append(("experiment samples", _number(exp["samples"])))
    ident = s.get("identification") or {}
    if isinstance(ident, dict):
        for key, label in (
            ("estimator", "estimator"),
            ("rows", "rows"),
            ("cond_W", "cond(W)"),
            ("residual_rms", "residual RMS"),
            ("param_rel_err", "parameter relative error"),
        ):
            if ident.get(key) is not None:
                rows.append((label, _number(ident[key])))
    if res.parameters:
        rows.append(("base parameters", str(len(res.parameters))))
    if res.validation is not None:
        rows.append(("validation relative error", _number(res.validation.relative_error)))
    if res.out is not None:
        rows.append(("output folder", str(res.out)))
    return rows


def validation_png(res: "StudyResult") -> Optional[bytes]:
    """The validation figure as PNG bytes: drawn with matplotlib (Agg, off screen) from the
    validation rows, else the study's own plots/validation_equation1.png when its folder is kept;
    None when neither is there."""
    v = res.validation
    if v is not None and v.equation is not None and len(v.equation) > 0:
        try:
            from matplotlib.figure import Figure
        except ImportError:
            Figure = None  # noqa: N806
        if Figure is not None:
            eqs = sorted(set(int(e) for e in v.equation))
            cols = min(3, len(eqs))
            nrows = (len(eqs) + cols - 1) // cols
            fig = Figure(figsize=(4.0 * cols, 2.4 * nrows))
            for k, e in enumerate(eqs):
                ax = fig.add_subplot(nrows, cols, k + 1)
                t, measured, predicted = v.of_equation(e)
                ax.plot(t, measured, lw=1.0, label="measured")
                ax.plot(t, predicted, lw=0.8, ls="--", label="predicted")
                ax.set_title(v.equations[e] if e < len(v.equations) else f"equation {e}", fontsize=9)
                ax.set_xlabel("t [s]", fontsize=8)
                ax.tick_params(labelsize=7)
                if k == 0:
                    ax.legend(fontsize=7)
            fig.suptitle(f"{res.name}: validation (relative error {v.relative_error:.4g})", fontsize=10)
            fig.tight_layout()
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=80)
            return buf.getvalue()
    if res.out is not None:
        png = res.out / "plots" / "validation_equation1.png"
        if png.is_file():
            return png.read_bytes()
    return None


def result_html(res: "StudyResult") -> str:
    esc = html.escape
    parts = [f"<div><strong>exid study {esc(res.name)}</strong>"]
    parts.append("<table><thead><tr><th>quantity</th><th>value</th></tr></thead><tbody>")
    parts += [f"<tr><td>{esc(k)}</td><td>{esc(v)}</td></tr>" for k, v in key_figures(res)]
    parts.append("</tbody></table>")
    if res.parameters:
        parts.append(
            "<table><thead><tr><th>parameter</th><th>value</th><th>std</th><th>nominal</th>"
            "<th>expression</th></tr></thead><tbody>"
        )
        for p in res.parameters[:_MAX_PARAMETERS]:
            parts.append(
                f"<tr><td>{esc(p.name)}</td><td>{_number(p.value)}</td><td>{_number(p.std)}</td>"
                f"<td>{_number(p.nominal)}</td><td>{esc(p.expression)}</td></tr>"
            )
        parts.append("</tbody></table>")
        if len(res.parameters) > _MAX_PARAMETERS:
            parts.append(
                f"<p>The first {_MAX_PARAMETERS} of {len(res.parameters)} parameters "
                "(all in <code>res.parameters</code>).</p>"
            )
    png = validation_png(res)
    if png is not None:
        data = base64.b64encode(png).decode("ascii")
        parts.append(f'<img alt="validation" src="data:image/png;base64,{data}"/>')
    parts.append("</div>")
    return "\n".join(parts)


def result_markdown(res: "StudyResult") -> str:
    lines = [f"**exid study {res.name}**", "", "| quantity | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in key_figures(res)]
    if res.parameters:
        lines += ["", "| parameter | value | std | nominal |", "|---|---|---|---|"]
        lines += [
            f"| {p.name} | {_number(p.value)} | {_number(p.std)} | {_number(p.nominal)} |"
            for p in res.parameters[:_MAX_PARAMETERS]
        ]
    return "\n".join(lines) + "\n"
