import { defineConfig } from 'vite';
import react from '@vitejs/plugin-react';

// The page: static/index.html + static/assets/*.js|css with content-hashed names.
export default defineConfig({
  plugins: [react()],
  base: './',
  build: {
    outDir: '../static',
    emptyOutDir: true,
    sourcemap: false,
    chunkSizeWarningLimit: 4000,
    rollupOptions: { output: { entryFileNames: 'assets/editor-[hash].js', chunkFileNames: 'assets/[name]-[hash].js', assetFileNames: 'assets/editor-[hash][extname]' } },
  },
  test: { include: ['test/**/*.test.ts'] },
});
