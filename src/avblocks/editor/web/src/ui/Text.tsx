// Text from the library's docstrings as the page shows it: `code` spans drawn as code
// (the palette's text comes with reStructuredText's roles already resolved: catalog.plain).

import type { ReactNode } from 'react';

export function Rich({ text }: { text: string | null | undefined }): ReactNode {
  if (!text) return null;
  const parts = text.split(/(`[^`]+`)/g);
  return (
    <>
      {parts.map((p, i) =>
        p.length > 2 && p.startsWith('`') && p.endsWith('`') ? (
          <code key={i} className="rich-code">
            {p.slice(1, -1)}
          </code>
        ) : (
          p
        ),
      )}
    </>
  );
}

/** The same text without the code marks (a title attribute, a tooltip). */
export function plainText(text: string | null | undefined): string {
  return (text ?? '').replace(/`([^`]+)`/g, '$1');
}
